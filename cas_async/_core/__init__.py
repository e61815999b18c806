"""The runtime (internal): layers, robots, swarms and what runs between them.

A :class:`~cas_async.Layer` (``_layer``) is run by its ``_layer_runtime`` (inbox:
``_channel``, ``_backpressure``; requests: ``_requests``, ``_deadlines``; timers:
``_timers``; counters: ``_counters``; what it calls on the user's layer and what the
layer sees: ``_hooks``); a :class:`~cas_async.Robot` (``_robot``, ``_robot_state``)
owns its layers, its ``_outbox`` and its ``_reception`` (with ``_dedup``) and
supervises them (``_supervision``); a :class:`~cas_async.Swarm` (``_swarm``) starts
and stops robots together. The transport contract every transport implements
(``_transport_contract``, and ``_unconnected`` for a robot without one) is here, so
that the runtime never imports a transport. ``_logs`` names robot and layer in every
line; ``_gc_policy`` sizes the garbage collector to the robots a process holds.

Imports the ground, ``_wire`` and ``_time``; never a transport, the simulator or the
scenario machinery.
"""

__all__: list[str] = []
