"""The onboard service: the asyncio daemon (:mod:`.daemon`), the intake from raw bytes to
the engine (:mod:`.intake`), the recordings and their replay (:mod:`.recorder`), the
adaptive state file (:mod:`.persistence`), MAVLink signing (:mod:`.signing`), systemd
notification (:mod:`.sdnotify`) and the publishers (:mod:`.publishers`)."""
