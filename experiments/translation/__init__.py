"""The translation lab: Table 1's experiment harness and its summary. Importing it registers the
paper's baseline translators (baselines.py) beside the product's."""

from experiments.translation import baselines  # noqa: F401  (registers the baselines' networks and configs)
