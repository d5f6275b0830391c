"""Pictures drawn from the models: worlds, runs and the paper's sensor figures (`twinbot plot`)."""
