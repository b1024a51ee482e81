"""``python -m groundstation``: the ``gs`` command (through its error boundary)."""

from groundstation.cli import main

main()
