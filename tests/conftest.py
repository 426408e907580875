"""Shared fixtures: scenes are built once per session (building a Panda scene runs IK)."""

from __future__ import annotations

import pytest

import coopdyn as cd


@pytest.fixture(scope="session")
def pandas() -> cd.Scene:
    """Two Pandas facing each other holding a 2 kg box, k = 1e4 N/m, no damping anywhere."""
    return cd.scenes.facing_arms("panda", stiffness=1e4)


@pytest.fixture(scope="session")
def book() -> cd.Scene:
    """The book's linear system with the book's parameters."""
    return cd.scenes.linear_book()


def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C tests send SIGINT to this process. A shell that starts a job in the background
    without job control (CI runners may) makes it ignore SIGINT, and Python then installs no
    KeyboardInterrupt handler: give it back, as an interactive run has it."""
    import signal

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def _private_tempdir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """Rescue folders and other temporary files of a test go to its own temporary tree, not /tmp."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path_factory.mktemp("tempdir")))
