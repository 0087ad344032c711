"""Episode metrics of the manipulation policy (greedy vs random on the test split)."""
