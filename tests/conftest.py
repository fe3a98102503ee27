import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def taxi():
    from nl2policy.domains import get_domain

    return get_domain("taxi")


@pytest.fixture(scope="session")
def highway():
    from nl2policy.domains import get_domain

    return get_domain("highway")
