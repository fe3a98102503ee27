import atexit
import os
import shutil
import tempfile

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# Tests never touch the user's data directory: models, databases and runs go to a fresh folder.
os.environ["NL2POLICY_HOME"] = tempfile.mkdtemp(prefix="nl2policy-test-")
atexit.register(shutil.rmtree, os.environ["NL2POLICY_HOME"], ignore_errors=True)


@pytest.fixture(scope="session")
def taxi():
    from nl2policy.domains import get_domain

    return get_domain("taxi")


@pytest.fixture(scope="session")
def highway():
    from nl2policy.domains import get_domain

    return get_domain("highway")


@pytest.fixture
def one_torch_thread():
    """One torch thread: the CI box has 2 cores, and oversubscribed threads crawl."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
