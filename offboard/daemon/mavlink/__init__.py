"""The daemon's MAVLink side: its link to its own vehicle (companion-computer view).

Entry point: :class:`offboard.daemon.mavlink.link.VehicleLink`.

* :mod:`.url` - the ``--mavlink`` URL; :mod:`.commands` - COMMAND_LONG, never blocking.
* :mod:`.sending` - what the link sends and how: setpoint, HEARTBEAT, sequence, signing.
* :mod:`.mode_requests`, :mod:`.offboard_keeper` - OFFBOARD/arm at start-up and after a failsafe.
* :mod:`.frame_peek`, :mod:`.stream_trim` - frames the daemon does not read.
* :mod:`.odometry` - the vehicle's ODOMETRY as kept, and the checks that admit one.
* :mod:`.lock_gate` - with signing, who may take the lock: fresh frames, answered challenge.
"""
