"""Real-rig drivers: one device per module, each implementing HAL ports and owning its scaling.

=================  ==========================================================================
module             device (ports)
=================  ==========================================================================
`canbus`           the CAN link: python-can bus, DBC (cantools), SYNC producer
`vlt`              VLT5003-style inverter: CAN set-points/status, Modbus FC profile (inverter)
`frontend`         measurement front-end, serial frame stream (currents, voltages, encoder)
`load`             DC-load torque command: CAN frame (default) or Modbus AO (load)
`modbus`           pymodbus client + Danfoss FC-profile register map
`rig`              the rig of these devices (`DriverRig`, `build_driver_rig`)
=================  ==========================================================================

`build_driver_rig` wires them from a rig file (``rig.driver = "drivers"``); docs/protocols.md
describes every byte. The `DriverRig` closes its connections on `deactivate` (and stops an
in-process emulator it was given), so a configure/activate cycle reopens them. It holds its devices'
locks (`riglock.RigLock`: one session per rig) from `configure` until it is closed.
"""
