"""``python -m fidelity`` runs the command line."""

from fidelity.cli import main

main()
