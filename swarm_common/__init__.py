"""``swarm_common``: what every package shares; it imports none of them.

* :mod:`swarm_common.scenario` - scenario files: schema, checks, feasibility, graphs.
* :mod:`swarm_common.mission` - formation missions: the ``[mission]`` table and its timed plan.
* :mod:`swarm_common.frames` - the one ENU/NED, FLU/FRD and quaternion boundary.
* :mod:`swarm_common.enums` - every choice as a ``StrEnum``; :mod:`swarm_common.px4` - PX4 modes.
* :mod:`swarm_common.wire`, :mod:`swarm_common.zenoh_session` - Zenoh keys, payloads, sessions.
* :mod:`swarm_common.signing`, :mod:`swarm_common.ports`, :mod:`swarm_common.faults` - MAVLink
  signing, the port scheme, seeded transport faults.
* :mod:`swarm_common.inputs` - untrusted input: bounded reads of regular files, finite
  numbers, the flag types every command shares, output paths checked before a run.
* :mod:`swarm_common.jit`, :mod:`swarm_common.fastnp`, :mod:`swarm_common.blas` - how the hot
  paths are compiled and run; :mod:`swarm_common.memo` - results computed once per object.
"""
