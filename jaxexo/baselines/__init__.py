"""Non-learned baselines the RL generator is judged against (thesis 3.1-3.4): CFFTG, a polynomial
collision-free foot trajectory generator (jaxexo.baselines.cfftg). NumPy-only, like jaxexo.inference,
whose RL generator also falls back on it."""

from jaxexo.baselines.cfftg import CFFTG

__all__ = ["CFFTG"]
