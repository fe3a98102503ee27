import atexit
import os
import shutil
import tempfile

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# One torch (OpenMP) thread in every test process and every process a test starts: two pytest
# workers share two cores, and a process whose threads outnumber its cores spin-waits, so a cold
# translation beside a training test crawled past its test's two-minute wait in CI.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
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
