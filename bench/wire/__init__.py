"""The rig's wire protocols, as codecs both sides import: the real drivers (`bench.drivers`) and the emulators of
the devices (`mock_hw.emulators`). A codec knows the bytes and words on the wire and nothing of either side.

* `bench.wire.frontend`: the measurement front-end's framed serial stream (LEMs, voltage bridge, encoder);
* `bench.wire.tcpcan`: CAN frames as records on a loopback TCP stream (the link to `bench emulate`);
* `bench.wire.canbus`: the CAN messages (the DBC, encoded with cantools) and the python-can bus of a rig file;
* `bench.wire.fc_profile`: the drive's Danfoss FC-profile control and status words and percent registers
  (over Modbus).

docs/protocols.md describes each.
"""
