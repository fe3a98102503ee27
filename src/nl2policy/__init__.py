"""nl2policy."""
