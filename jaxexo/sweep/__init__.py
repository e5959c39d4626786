"""Hyperparameter sweeps (``jaxexo sweep``): many configurations x seeds trained as one compiled program;
``spec``, ``plan``, ``program``, ``runner``, ``report`` (docs/training.md, "Hyperparameter sweeps").
Importing this package (and ``spec``, ``plan``) does not import JAX.
"""
