"""``python -m ftc_hw`` runs the ``ftc`` command."""
from .cli import run

if __name__ == "__main__":  # not when a spawned process imports the parent's main module as __mp_main__
    run()
