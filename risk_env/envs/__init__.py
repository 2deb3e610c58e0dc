"""The environments: :class:`~risk_env.envs.env.RiskCrossingEnv` (``"RiskCrossing-v0"``), its
batched numpy form, the pure transition both step with, the episodes' seeded variations and the
constructor arguments."""
