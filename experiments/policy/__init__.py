"""The policy lab (``python -m experiments.policy``): Table 2, fidelity, corpus returns."""
