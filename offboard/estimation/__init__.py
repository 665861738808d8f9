"""What a follower knows: sensing, observers and neighbour data (pure maths, no I/O).

Entry points:

* :func:`offboard.estimation.bearing.formation_from_scenario` - bearings, graph and the
  bearing Laplacian of a scenario's formation.
* :class:`offboard.estimation.sensing.Sensor` - relative bearing/range measurements.
* :class:`offboard.estimation.deso.DESO` - the distributed extended state observer;
  :mod:`offboard.estimation.deso_gains` checks its gains.
* :class:`offboard.estimation.reference.DesiredStateObserver` - the desired state from the
  leaders'.
* :class:`offboard.estimation.formation_frame.FormationFrameObserver` - that observer for a
  yawing formation, run in its frame; :mod:`offboard.estimation.yaw_turn` turns jets by
  the formation's yaw.
* :class:`offboard.estimation.predictor.NeighbourPredictor` and
  :class:`offboard.estimation.peer_table.PeerTable` - received estimates, aged to now.
* :mod:`offboard.estimation.neighbour_accel` - neighbours' accelerations from their velocities.

``*_kernel`` modules are the numba-compiled steps of the module of the same stem.
"""
