"""The translation lab: Table 1's experiment harness, its summaries and probes."""
