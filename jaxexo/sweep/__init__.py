"""Hyperparameter sweeps (``jaxexo sweep``): many configurations x seeds trained as one compiled program.

- ``jaxexo.sweep.spec``: sweep files (a base config plus grid and random axes and seeds), validated
  and expanded into configurations, grouped by static settings (NumPy only);
- ``jaxexo.sweep.plan``: the memory estimate of one agent and the split of each group into chunks;
- ``jaxexo.sweep.program``: a group's ``jit(shard_map(vmap(train + evaluation)))`` and one chunk's run (JAX);
- ``jaxexo.sweep.runner``: the local and Ray backends, results.csv, resume, the progress bar;
- ``jaxexo.sweep.report``: summary.md, the heatmap and learning-curve figures, ``--export-best``.

Importing this package (and ``spec``, ``plan``) does not import JAX.
"""
