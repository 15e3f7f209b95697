"""``python -m ftc_hw`` runs the ``ftc`` command."""
from .cli import app

app(prog_name="ftc")
