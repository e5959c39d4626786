"""``python -m jaxexo.cli``: the ``jaxexo`` command."""

try:
    from jaxexo.cli import run
except RuntimeError as e:
    # Ctrl-C while the imports make a class arrives wrapped (Python 3.11 raises a RuntimeError from
    # an exception in __set_name__): Python's own interrupt, as a Ctrl-C anywhere else in them.
    if isinstance(e.__cause__, KeyboardInterrupt):
        raise e.__cause__ from None
    raise

run()
