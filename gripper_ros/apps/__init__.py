"""Console applications: the demo, the client, the paper's tables, the sweeps."""
