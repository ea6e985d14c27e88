"""Build of the optional C scanner kernel; everything else is in pyproject.toml.

``optional=True``: without a C compiler the install still succeeds, and the capture
scanner runs on numba or plain Python instead (``lolacli.capture.fast.choose_engine``).
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "lolacli.capture._cscan",
            sources=["lolacli/capture/_cscan.c"],
            extra_compile_args=["-O2", "-std=c99", "-Wall", "-Wno-maybe-uninitialized"],
            optional=True,
        )
    ]
)
