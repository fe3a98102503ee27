"""Policies that act in the envs: lexical trees, DDTs, baselines; and how they are scored."""
