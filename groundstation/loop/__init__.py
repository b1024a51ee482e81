"""The flight loop: supervisor, flight core, real-time daemon, recorder."""
