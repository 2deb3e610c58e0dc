"""Drawing, kept apart from the numerics: the basic matplotlib renderer
(:mod:`~risk_env.render.rendering`) and the choice of renderer (:mod:`~risk_env.render.renderers`)."""
