"""``python -m negstiff``: the command line."""

from negstiff.cli import run

run()
