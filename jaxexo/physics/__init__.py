"""Physics layer: obstacle geometry, leg kinematics, reward terms and the transition rules, each
written once against the array module it is given (numpy, jax.numpy or Python scalars).

Nothing here imports JAX; the JAX environment (``jaxexo.env``) and the NumPy generator
(``jaxexo.inference``) both call these functions."""
