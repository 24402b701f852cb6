import pytest


@pytest.fixture
def discovery_range() -> str:
    """Replay tests talk to child processes: discovery on this host, isolation by the reserved domain id."""
    return "LOCALHOST"
