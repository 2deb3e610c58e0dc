"""The models, each written once over the maths faces of :mod:`~risk_env.models.ops` (numpy,
CasADi, Python floats): the unicycle (:mod:`~risk_env.models.dynamics`), the reference path and the
timing law (:mod:`~risk_env.models.path`), truncated normals (:mod:`~risk_env.models.truncnorm`)."""
