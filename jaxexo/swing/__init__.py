"""The swing: what every generator (jaxexo.inference's policy, jaxexo.baselines' CFFTG) does with the
heel path it plans, NumPy only. Its modules are listed in docs/architecture.md, "Layers"; nothing is
imported here, which keeps ``import jaxexo.inference`` fast.
"""
