"""PPO (Stable-Baselines3) with a DDT actor, and the paper's two baselines.

``DDTPolicy`` is SB3's ``ActorCriticPolicy`` with the action head swapped: the actor sees the
raw six features (an empty ``pi`` MLP) and the DDT maps them to log mixture probabilities,
which SB3's ``CategoricalDistribution`` takes as logits. The critic stays a small MLP
(64-64), so value learning does not disturb the tree. Every method sees the same features.

PPO's settings and the actor's learning-rate scale are the domain's knobs (``Domain.knobs``,
``domains/<name>/spec.toml``, with their reasons); ``make_ppo`` takes other knobs for experiments.
"""

from __future__ import annotations

import copy
from typing import Optional

import gymnasium as gym
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecMonitor

from nl2policy.domains import get_domain, make_env
from nl2policy.domains.spec import Knobs
from nl2policy.policy.convert import tree_to_ddt
from nl2policy.policy.ddt import DDT, random_ddt
from nl2policy.policy.vec_env import SB3VecEnv
from nl2policy.trees import Tree

METHODS = ("tree_ddt", "random_ddt", "mlp")
CRITIC = [64, 64]
class TreePPO(PPO):
    """SB3 PPO that honours a per-parameter-group ``lr_scale`` (SB3 itself sets every group's
    learning rate to the schedule's value before each update)."""

    def _update_learning_rate(self, optimizers) -> None:
        super()._update_learning_rate(optimizers)
        for optimizer in optimizers if isinstance(optimizers, list) else [optimizers]:
            for group in optimizer.param_groups:
                group["lr"] *= group.get("lr_scale", 1.0)

    def _setup_learn(self, *args, **kwargs):
        # SB3's default logger for a quiet run without tensorboard still makes an empty folder
        # /tmp/SB3-<time> on every learn(): one per optimization, test and resumed chunk. Ours
        # records the same values and writes nowhere.
        if self.verbose == 0 and not self._custom_logger:
            self.set_logger(Logger(folder=None, output_formats=[]))
        return super()._setup_learn(*args, **kwargs)


class DDTPolicy(ActorCriticPolicy):
    """Actor = a copy of the given DDT; critic = MLP. Pass the DDT as ``policy_kwargs={"ddt": ...}``
    (it is pickled with the model, so ``PPO.load`` rebuilds the same shape)."""

    def __init__(self, *args, ddt: DDT, actor_lr_scale: float = 1.0, **kwargs) -> None:
        self._make_actor = lambda: copy.deepcopy(ddt)  # a plain attribute: set before nn.Module init
        self._actor_lr_scale = actor_lr_scale
        kwargs.setdefault("net_arch", dict(pi=[], vf=CRITIC))
        super().__init__(*args, **kwargs)

    def _build(self, lr_schedule) -> None:
        super()._build(lr_schedule)
        self.action_net = self._make_actor()  # latent_pi is the raw feature vector (pi=[])
        actor = set(map(id, self.action_net.parameters()))
        rest = [p for p in self.parameters() if id(p) not in actor]
        lr = lr_schedule(1)
        groups = [dict(params=rest, lr_scale=1.0),
                  dict(params=list(self.action_net.parameters()), lr_scale=self._actor_lr_scale,
                       lr=lr * self._actor_lr_scale)]
        self.optimizer = self.optimizer_class(groups, lr=lr, **self.optimizer_kwargs)


SIMULATORS = ("fast", "reference")


def make_vec_env(domain: str, seed: int, simulator: str = "fast") -> VecEnv:
    """The env PPO trains on, seeded: the domain's fast vector env (``train_env_id``, the
    knobs' ``train_envs`` episodes side by side) where it has one and `simulator` is "fast";
    else one episode at a time of its reference env (``env_id``). Episode returns come from
    SB3's monitors either way."""
    if simulator not in SIMULATORS:
        raise ValueError(f"unknown simulator {simulator!r}; choose one of {', '.join(SIMULATORS)}")
    d = get_domain(domain)
    if simulator == "fast" and d.train_env_id is not None:
        vector = gym.make_vec(d.train_env_id, num_envs=d.knobs.train_envs, vectorization_mode="vector_entry_point")
        env = VecMonitor(SB3VecEnv(vector))
        env.seed(seed)
        return env

    def build():
        env = Monitor(make_env(domain))
        env.reset(seed=seed)
        return env

    return DummyVecEnv([build])


def initial_actor(domain: str, method: str, seed: int, tree: Optional[Tree] = None,
                  knobs: Optional[Knobs] = None) -> Optional[DDT]:
    """The DDT a method starts from (None for the MLP)."""
    d = get_domain(domain)
    knobs = knobs or d.knobs
    if method == "tree_ddt":
        if tree is None:
            raise ValueError("tree_ddt needs a tree")
        return tree_to_ddt(domain, tree, pad=True, knobs=knobs)
    if method == "random_ddt":
        return random_ddt(len(d.features), len(d.actions), knobs.ddt_gamma, depth=3, seed=seed)
    if method == "mlp":
        return None
    raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")


def make_ppo(domain: str, method: str, seed: int, tree: Optional[Tree] = None, env=None,
             knobs: Optional[Knobs] = None, simulator: str = "fast") -> PPO:
    """PPO for `method` with the domain's knobs, or `knobs` where an experiment varies them,
    on `env` or else ``make_vec_env(domain, seed, simulator)``."""
    env = env or make_vec_env(domain, seed, simulator)
    knobs = knobs or get_domain(domain).knobs
    settings = knobs.ppo.as_kwargs()
    actor = initial_actor(domain, method, seed, tree, knobs)
    if actor is not None:
        actor.anneal_to, actor.sharpen_to = knobs.leaf_temperature_end, knobs.node_sharpness_end
        actor.sharpen_from, actor.anneal_from = knobs.node_sharpness_from, knobs.leaf_temperature_from
        if method == "tree_ddt" and not knobs.learn_node_features:
            # each node keeps the feature its question tests (a readable test: the question, or a
            # threshold on its feature); only comparators and leaves learn. The flag travels with
            # the pickled DDT, so a resumed run keeps it; Adam skips a parameter with no gradient.
            actor.weights.requires_grad_(False)
    if actor is None:  # 3 fully connected layers in the actor: 64, 64, action head
        return TreePPO("MlpPolicy", env, policy_kwargs=dict(net_arch=dict(pi=[64, 64], vf=CRITIC)),
                       seed=seed, device="cpu", verbose=0, **settings)
    kwargs = dict(ddt=actor, actor_lr_scale=knobs.actor_lr_scale)
    return TreePPO(DDTPolicy, env, policy_kwargs=kwargs, seed=seed, device="cpu", verbose=0, **settings)


def actor_ddt(model: PPO) -> DDT:
    return model.policy.action_net


def soft_act_fn(model: PPO, deterministic: bool):
    """Act with a trained PPO policy on one observation."""
    def act(x) -> int:
        action, _ = model.predict(x, deterministic=deterministic)
        return int(action)

    return act



def action_probs_fn(model: PPO):
    """The trained policy's action probabilities for a batch of feature vectors (n, features):
    what it samples from when it acts stochastically."""
    import torch

    def probs(X):
        with torch.no_grad():
            obs = torch.as_tensor(X, dtype=torch.float32, device=model.policy.device)
            return model.policy.get_distribution(obs).distribution.probs.cpu().numpy()

    return probs
