"""Non-learned baselines the RL generator is judged against (thesis 3.1-3.4): CFFTG, a polynomial
collision-free foot trajectory generator. NumPy-only, like jaxexo.inference, where it lives beside the
RL generator (it is also the RL generator's fallback planner)."""

from jaxexo.inference.cfftg import CFFTG

__all__ = ["CFFTG"]
