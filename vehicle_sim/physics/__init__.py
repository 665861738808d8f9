"""The physics of the swarm and the vehicle's own low-level control (pure, no I/O).

Entry point: :class:`vehicle_sim.physics.dynamics.SwarmDynamics` (vectorised over N
vehicles; compiled step in :mod:`.dynamics_kernel`, its pair distances and contacts in
:mod:`.contacts_kernel`).

* :mod:`.position_control` - position / velocity / acceleration to attitude and thrust.
* :mod:`.failsafe_controller` - the onboard hold / land controller.
* :mod:`.battery`, :mod:`.geo` - the battery model and the flat-earth geodetic frame.
"""
