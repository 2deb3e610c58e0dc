"""The MPC's nonlinear program and its solver: the optimal control problem
(:mod:`~agents.mpc.nlp.ocp`) with the episode risk budget's rows
(:mod:`~agents.mpc.nlp.risk_budget`), the solver built from it with its rungs and caches
(:mod:`~agents.mpc.nlp.solver`), compiled code (:mod:`~agents.mpc.nlp.compiled`) and the time
budget of a step's calls (:mod:`~agents.mpc.nlp.budget`)."""
