"""Time (internal): the clocks, the virtual-time loop, and effects due later.

The only place that reads the time or sleeps: ``_clock`` (scaled real time, virtual
time), ``_virtual_loop`` (a loop that jumps over idle time), ``_loop_factory`` (which
loop a program runs on), ``_loop_timers`` and ``_precise_selector`` (timers never
early), ``_deliveries`` (one robot's effects on another, due a latency later, in a
fixed order) and ``_wall`` (bounded waits on the wall clock from a virtual loop).

Imports only the ground (``cas_async._errors``, ``cas_async._types``).
"""

__all__: list[str] = []
