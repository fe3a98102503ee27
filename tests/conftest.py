import os
import tempfile

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# Tests never touch the user's data directory: models, databases and runs go to a fresh folder.
os.environ["NL2POLICY_HOME"] = tempfile.mkdtemp(prefix="nl2policy-test-")


@pytest.fixture(scope="session")
def taxi():
    from nl2policy.domains import get_domain

    return get_domain("taxi")


@pytest.fixture(scope="session")
def highway():
    from nl2policy.domains import get_domain

    return get_domain("highway")
