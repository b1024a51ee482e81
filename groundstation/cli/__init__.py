"""The `gs` command line.

Each command is a thin shell: parse options, load the configuration, assemble it
(:mod:`groundstation.flight.assembly`), call the package. :func:`main` (the console entry
point) is the one error boundary around all of them: a one-line ``error: ...`` and a
documented exit code, never a traceback, for a user's mistake.

Modules: :mod:`.commands` (the commands and :func:`main`), :mod:`.options` (what the
commands share: one name per meaning), :mod:`.api` (``gs goto``, ``gs land``, ``gs hold``,
``gs status``), :mod:`.fleet` (``gs fleet ...``, ``gs vicon-relay``). The installed
virtual lab adds its own (``gs sim-device``, ``gs eval``; :mod:`groundstation.lab`).
"""

from groundstation.cli.commands import add_lab_commands, app, load, main

from groundstation.cli.api import register as register_api_commands  # isort: skip
from groundstation.cli.fleet import register as register_fleet_commands  # isort: skip

__all__ = ["app", "load", "main"]

add_lab_commands()  # gs sim-device, gs eval: after load is importable here (the lab uses it)
register_api_commands(app)  # gs goto, land, hold, status
register_fleet_commands(app)  # gs fleet ..., gs vicon-relay
