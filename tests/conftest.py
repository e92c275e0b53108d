"""Session set-up shared by every test module."""

import pytest

from grazing_control.oscillator import kernel


@pytest.fixture(scope="session", autouse=True)
def compiled_kernel():
    """Compile the numba kernel (or load its on-disk cache) once, before any test: in a
    fresh checkout the first compilation takes 5-20 s, which a node test's startup
    timeouts must not absorb."""
    if kernel.use_kernel():
        kernel.warm_up()
