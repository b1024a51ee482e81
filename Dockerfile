# Ground-station flight daemon image (no dev extras: no pytest, mypy, plotting), and
# without the virtual lab: sim_device is not copied, so the image has no `gs sim-device`,
# `gs eval` or `gs fly --demo` (they say the virtual lab is not installed). Fly the
# virtual lab from a checkout (`make demo`).
#
# Build:  docker build -t groundstation .
# Fly:    docker run --rm -it --init --network host --stop-timeout 30 \
#             --device /dev/ttyUSB0 --ulimit rtprio=10 \
#             -v /etc/groundstation/lab.yaml:/etc/groundstation/lab.yaml:ro \
#             -v gs-flightlogs:/var/lib/groundstation \
#             groundstation
#
# Notes for the lab:
# * --device /dev/ttyUSB0 passes the XBee/USB-serial adapter; the node keeps the
#   host's group, so the image user is in group dialout (gid 20 on Debian/Ubuntu
#   hosts). If the host's dialout has another gid add `--group-add <gid>`.
# * --network host: the Vicon UDP stream (port 51001/udp, vicon.port) arrives on
#   the host's interface, with no NAT in the 100 Hz path. With bridge networking
#   publish the ports instead (-p 51001:51001/udp -p 5556:5556) and set
#   telemetry.endpoint to tcp://*:5556 in lab.yaml (its default 127.0.0.1 is the
#   container's own loopback).
# * --ulimit rtprio=10 lets the daemon run its loop under the real-time FIFO policy
#   (realtime.fifo_priority); without it the daemon warns and flies under the normal
#   policy, which lets busy neighbours delay COMMANDs (README, "Real-time tuning").
#   A kernel with real-time group scheduling (CONFIG_RT_GROUP_SCHED) also needs
#   --cpu-rt-runtime=950000 (Docker's "realtime scheduler" documentation).
# * --stop-timeout 30: `docker stop` sends SIGTERM, on which the daemon lands; the
#   default 10 s before SIGKILL may be too short to land (see groundstation.service).
#   A second SIGTERM (`docker kill -s TERM`) hands back to the pilot at once.
# * --init runs tini as PID 1 to forward signals and reap any child processes.
# * Flight logs are written to /var/lib/groundstation/flightlogs (lab.yaml); keep
#   them in a volume. A bind mount must be writable by uid `groundstation`.
# * No HEALTHCHECK: `gs fly` is one flight, not a long-running service, and
#   Docker does not act on "unhealthy"; watch a flight with `gs monitor`.
# * `gs channels` (run-time channel handover) and the run-time API (`gs goto`, `gs land`,
#   `gs hold`, `gs status`, groundstation.client; fly with `gs fly --trajectory none`)
#   talk to the daemon's control socket, 127.0.0.1:5557 by default and deliberately not
#   exposed: run them on the host with --network host, or `docker exec <container> gs
#   status`. Serving clients on other machines needs CURVE keys (`gs keys`, README).
# * CPU wake-up latency (realtime.cpu_dma_latency_us): to hold the request, add
#   `--device /dev/cpu_dma_latency` with the host's udev rule
#   (config/99-groundstation.rules) giving the container user's group write access
#   (`--group-add <gid>`); without it the daemon logs a warning and flies anyway.

FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY groundstation ./groundstation
# Wheels for the package and its runtime dependencies only (the virtual lab, sim_device/,
# stays out: the package finder finds no sim_device here).
RUN python -m pip wheel --no-cache-dir --wheel-dir /wheels .

FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1
RUN useradd --system --user-group --groups dialout --no-create-home \
        --home-dir /var/lib/groundstation --shell /usr/sbin/nologin groundstation \
    && install -d -o groundstation -g groundstation -m 0750 \
        /var/lib/groundstation /var/lib/groundstation/flightlogs
COPY --from=build /wheels /wheels
# The version is pinned by the wheels built above; --no-index: nothing else is fetched.
# hadolint ignore=DL3013
RUN python -m pip install --no-index --find-links /wheels groundstation \
    && rm -rf /wheels
COPY config/lab.yaml config/lab-ll.yaml /etc/groundstation/

# By name so the dialout membership from /etc/group reads clearly.
# hadolint ignore=DL3066
USER groundstation
WORKDIR /var/lib/groundstation
VOLUME ["/var/lib/groundstation"]
# Vicon UDP object stream (vicon.port) and the telemetry PUB socket (telemetry.endpoint).
EXPOSE 51001/udp 5556/tcp
STOPSIGNAL SIGTERM
ENTRYPOINT ["gs"]
CMD ["fly", "--config", "/etc/groundstation/lab.yaml"]
