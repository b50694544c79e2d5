"""The tactile device bridge (device-bridge/README.md): drivers, the 1 kHz tick, interpolation, safety."""
