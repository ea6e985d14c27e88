"""Build of the optional C kernels; everything else is in pyproject.toml.

``optional=True``: without a C compiler the install still succeeds; the capture scanner
then runs its plain-Python reference (``lolacli.capture.fast.choose_engine``; ``capture
analyze`` says so on stderr) and the emulated chain its Python reference code
(``lolacli.emulator.chain.chain_engine``).
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
