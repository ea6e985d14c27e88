"""Build of the optional C kernels; everything else is in pyproject.toml.

``optional=True``: without a C compiler the install still succeeds; the capture scanner
then runs on numba or plain Python (``lolacli.capture.fast.choose_engine``) and the
emulated chain on its Python reference code (``lolacli.emulator.chain.chain_engine``).
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "lolacli.capture._cscan",
            sources=["lolacli/capture/_cscan.c"],
            extra_compile_args=["-O2", "-std=c99", "-Wall", "-Wno-maybe-uninitialized"],
            optional=True,
        ),
        Extension(
            "lolacli.emulator._ccore",
            sources=["lolacli/emulator/_ccore.c"],
            # ISO C without contraction: no fused multiply-add, so the analog inputs'
            # sines are the same doubles as Python's
            extra_compile_args=["-O2", "-std=c11", "-Wall", "-Wextra", "-ffp-contract=off"],
            libraries=["m"],
            optional=True,
        ),
    ]
)
