"""Eclipse Zenoh (the ``zenoh`` extra): robots in any process or host, and its plumbing.

* :class:`ZenohTransport`: robots discovered by liveliness tokens, reliable
  delivery, one subscriber per process (also exported by ``cas_async``);
* :func:`loopback_config`: a Zenoh session configuration that stays on this
  machine (the default of everything here), on a free port when asked;
* :func:`import_zenoh`: the ``zenoh`` module, or a :class:`~cas_async.ConfigurationError`
  that says which extra to install;
* :class:`ThreadInbox`: what Zenoh's threads receive, handed to the event loop in
  batches with one wake-up each.

The run across processes and :mod:`cas_async.ros` build on these.
"""

from ._sessions import import_zenoh, loopback_config
from ._thread_inbox import ThreadInbox
from ._transport import ZenohTransport

__all__ = ["ThreadInbox", "ZenohTransport", "import_zenoh", "loopback_config"]
