"""X-3D serial protocol: CRC16, messages, sans-IO stream decoder, serial link.

See ``shared/spec/x3d-serial-protocol.md``; everything here follows it byte for byte.
"""
