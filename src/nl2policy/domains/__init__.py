"""The domains: one folder each, found, not listed.

A domain is a folder ``<name>/`` holding ``spec.toml`` (its dictionary of questions and actions,
what each question tests on the features, its environment and knobs), ``phrases.toml`` (how the
synthetic generator words it), the code of its environment, and its shipped translator
(``translator-<version>.pt``). The built-in ones live beside this file; a user adds their own
robot by pointing ``NL2POLICY_DOMAINS`` at folders (os.pathsep-separated), each a domain folder
or a folder of them. Extra folders join this package's ``__path__`` (as ``pkgutil.extend_path``
does), so a domain's code is always ``nl2policy.domains.<name>`` and its relative imports, its
envs' entry points and pickles work the same in worker processes, which find it the same way.

Every domain's envs are registered with Gymnasium when this package is imported: the ids come
from the folder's name (``spec.env_ids``), so a copy under a new name has ids of its own.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import gymnasium as gym

from nl2policy.domains.spec import Domain, env_ids, load_domain, read_spec

BUILT_IN = Path(__file__).resolve().parent
EXTRA_ENV = "NL2POLICY_DOMAINS"
PROBLEMS: list[str] = []
"""Why a folder NL2POLICY_DOMAINS names was left out (a broken spec, a name taken): importing
this package never fails on a user's folder; the command line refuses to run until it is fixed."""


def _candidates(root: Path) -> list[Path]:
    """`root` itself if it is a domain folder, else its subfolders that are."""
    if (root / "spec.toml").is_file():
        return [root]
    return sorted(p for p in root.iterdir() if (p / "spec.toml").is_file()) if root.is_dir() else []


def _discover() -> dict[str, tuple[Path, dict]]:
    """Every domain folder with its spec, by name: the built-in ones, then NL2POLICY_DOMAINS's,
    each group in the order its specs' `order` keys give (then by name)."""
    specs = {p.name: (p, read_spec(p)) for p in _candidates(BUILT_IN)}
    for entry in filter(None, os.environ.get(EXTRA_ENV, "").split(os.pathsep)):
        for folder in _candidates(Path(entry).expanduser().resolve()):
            try:
                if not folder.name.isidentifier():
                    raise ValueError(f"a domain folder's name must be a Python identifier, not {folder.name!r}")
                if folder.name in specs and specs[folder.name][0] != folder:
                    raise ValueError(f"domain {folder.name!r} in {folder.parent} is already {specs[folder.name][0]}")
                specs[folder.name] = (folder, read_spec(folder))
            except ValueError as exc:  # the user's folder, not the package: said once, by whoever runs (cli.main)
                PROBLEMS.append(f"{EXTRA_ENV}: {exc}")
                continue
            if str(folder.parent) not in __path__:
                __path__.append(str(folder.parent))

    def order(item: tuple[str, tuple[Path, dict]]) -> tuple[bool, float, str]:
        folder, spec = item[1]
        return folder.parent != BUILT_IN, float(spec.get("order", float("inf"))), item[0]

    return dict(sorted(specs.items(), key=order))


_SPECS = _discover()
FOLDERS = {name: folder for name, (folder, _) in _SPECS.items()}
DOMAINS = tuple(FOLDERS)


def _register(name: str, spec: dict) -> None:
    """Register the folder's envs under ids made from its name (an env named by id is Gymnasium's)."""
    env_id, train_id = env_ids(name, spec)
    package = f"{__name__}.{name}"
    if "entry_point" in spec.get("env", {}) and env_id not in gym.registry:
        gym.register(env_id, entry_point=f"{package}.{spec['env']['entry_point']}")
    if train_id is not None and train_id not in gym.registry:
        train = spec["train_env"]
        gym.register(train_id, entry_point=f"{package}.{train['entry_point']}",
                     vector_entry_point=f"{package}.{train['vector_entry_point']}" if "vector_entry_point" in train else None)


for _name, (_, _spec) in _SPECS.items():
    _register(_name, _spec)


@lru_cache(maxsize=None)
def get_domain(name: str) -> Domain:
    """The domain called `name`; a clear KeyError naming the known ones otherwise."""
    if name not in FOLDERS:
        raise KeyError(f"unknown domain {name!r}; choose one of: {', '.join(DOMAINS)}")
    folder, spec = _SPECS[name]
    return load_domain(folder, f"{__name__}.{name}", spec)


def make_env(name: str, **kwargs) -> gym.Env:
    return gym.make(get_domain(name).env_id, **kwargs)


__all__ = ["DOMAINS", "PROBLEMS", "Domain", "get_domain", "make_env"]
