"""The web app: describe a policy, inspect and edit its tree, optimize it, collect new specs."""
