"""Limits on what a user may ask for, shared by the CLI and the web API so both refuse the same
input with the same words (a description the API refuses is refused by the CLI too).

Nothing here imports anything heavy: the CLI reads these before it loads a model.
"""

from __future__ import annotations

MAX_DESCRIPTION = 5000
"""Characters in a description; the corpus's longest is about 1,500."""

MAX_SEED = 2**32 - 1
"""numpy and gymnasium take seeds in [0, 2^32 - 1]; a larger one makes a run fail later."""

MAX_STEPS = 200_000
"""PPO steps one web run may ask for: the server trains one run at a time on a shared machine."""

MAX_BODY_BYTES = 1_000_000
"""Largest request body the web API reads (a tree or a description is a few KB)."""

MAX_WAITING_RUNS = 20
"""Queued runs the server keeps: more would only hold the machine for hours."""


MAX_CLI_STEPS = 100_000_000
"""PPO steps one command may ask for: about a day of PPO on one core here (ppo_overhead
benchmark: ~1,000-2,000 steps a second); more is a typo, not a plan."""

MAX_EPISODES = 1_000_000
"""Episodes or sampled states one command may ask for (a million taxi episodes take hours)."""

MAX_COUNT = 10_000
"""Any other count a command takes (candidate trees, seeds, workers)."""


MAX_MESSAGE = 400
"""Characters of any one error message: messages quote what was given, which may be huge."""


def clipped(text: str, limit: int = MAX_MESSAGE) -> str:
    """`text`, or its first `limit` characters and how long it was."""
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text):,} characters)"


def has_visible(text: str) -> bool:
    """Whether `text` shows anything: a character that is not a space, a control or a format
    character (zero-width spaces and joiners, byte-order marks) or unassigned."""
    import unicodedata

    return any(unicodedata.category(c)[0] not in "ZC" for c in text)


def text_problem(text: str, what: str = "the text") -> str | None:
    """Why `text` cannot be stored or read as text: characters that are not Unicode (a lone
    surrogate, from invalid UTF-8 or a JSON escape such as \\ud800). Never quotes them."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError as exc:
        return f"{what} is not valid Unicode text (character {exc.start + 1} is a lone surrogate, e.g. from invalid UTF-8)"
    return None


def description_problem(text: str) -> str | None:
    """Why a description cannot be translated, or None when it can be."""
    problem = text_problem(text, "the description")
    if problem:
        return problem
    if not has_visible(text):
        return "the description is empty: say what the robot should do"
    if len(text) > MAX_DESCRIPTION:
        return f"the description is {len(text):,} characters long; the limit is {MAX_DESCRIPTION:,}"
    return None


def rollout_steps(domain: str, simulator: str = "fast") -> int:
    """PPO's rollout length for `domain`: training runs in whole rollouts, so a run of N steps
    trains N rounded up to a multiple of it (``optimize --steps 1`` trains one rollout). On a
    fast vector env (highway's twin) a rollout is n_steps from each of its episodes."""
    from nl2policy.domains import get_domain

    d = get_domain(domain)
    envs = d.knobs.train_envs if simulator == "fast" and d.train_env_id is not None else 1
    return d.knobs.ppo.n_steps * envs


def steps_problem(domain: str, steps: int, option: str = "steps", simulator: str = "fast") -> str | None:
    """Why `steps` cannot be trained as asked, or None."""
    rollout = rollout_steps(domain, simulator)
    if steps < rollout:
        return (f"{option} {steps} is less than one PPO rollout: {domain} trains in rollouts of {rollout} steps, "
                f"so ask for at least {rollout}")
    return None


def trained_steps(domain: str, steps: int, simulator: str = "fast") -> int:
    """The steps a run asked for `steps` really trains: rounded up to whole rollouts."""
    rollout = rollout_steps(domain, simulator)
    return -(-steps // rollout) * rollout
