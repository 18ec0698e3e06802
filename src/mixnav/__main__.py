"""``python -m mixnav``: the command line of :mod:`mixnav.cli`, for an environment whose scripts
folder is not on PATH (the same commands as ``mixnav``)."""

from .cli import app

app(prog_name="mixnav")
