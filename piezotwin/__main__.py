"""`python -m piezotwin` runs the command line."""

from piezotwin.cli import app

app()
