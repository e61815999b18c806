"""Operational robots on the same transport as simulated ones: the rendezvous example.

* :mod:`.messages`, :mod:`.layers`: the application, two layers; they run unchanged
  in simulation and in operation.
* :mod:`.simulated`: a swarm of simulated robots in one process, on Zenoh.
* :mod:`.driver`, :mod:`.robot`: one robot alone in its process, with a middleware
  that is not the simulator (a stub driver that logs its commands).

See README.md beside this file.
"""
