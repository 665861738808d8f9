"""The daemon's Zenoh side: truth, neighbours' estimates and commands in; its own out.

Entry point: :class:`offboard.daemon.zenoh.link.SwarmBus`.

* :mod:`.shared_subs`, :mod:`.shared_batch` - one set of subscriptions for a packed process.
* :mod:`.step_store` - payloads kept by control step.
"""
