"""A run across processes (internal): one world, N workers, lookahead windows.

The protocol, on virtual time (``run --processes N --virtual``):

1. **Joining.** The world (``_world``) opens a Zenoh session and its lobby
   (``_lobby``); each worker (``_worker``, started by ``_children`` or by hand)
   says hello and is welcomed with its place: the scenario, its seed and the
   robots it runs (``_partition``), or refused (``_joining``). Every control
   message (``_control``) is typed, signed with the run's key and never replayed.
2. **Windows.** A window (``_windows``) is a span of simulated time no longer than
   the network latency ``L``: nothing one robot does reaches another sooner, so
   each worker runs every event before the window's end without hearing from
   anyone. It then publishes its window (what its robots did and sent to other
   workers' robots, its next event) with a promise: nothing it does reaches
   another worker before that instant. Each worker's next window ends at the
   least promise of the workers it depends on (all others; with an interaction
   range, those whose robots can come within range of its own: ``_halo``), so a
   worker far from the rest runs ahead. Effects between workers (``_network``)
   arrive in a fixed order, so a run gives the same results in any number of
   processes.
3. **Observing.** The world keeps a mirror of the robots' Environment
   (``_observer``), fed in that same order up to the least instant every worker
   reached: the objective, the trace and progress read it, and the world lets
   the workers run at most two steps of ``run.credit`` ahead of it.
4. **Ending.** The world tells the workers when the run ends; a worker that stops
   answering is declared lost (``_liveness``, ``_lost``) with its robots; the
   world sums every worker's counts (``_tally``) and what the windows cost
   (``_window_costs``).

On scaled time the workers run freely and report as they go; the world follows.
"""

__all__: list[str] = []
