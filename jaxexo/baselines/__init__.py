"""Non-learned baselines the RL generator is judged against (thesis 3.1-3.4): CFFTG, a polynomial
collision-free foot trajectory generator. NumPy-only, like jaxexo.inference."""

from jaxexo.baselines.cfftg import CFFTG

__all__ = ["CFFTG"]
