"""A layer's message loop (thesis Fig. 10), and back-pressure between layers.

One task per layer runs :func:`run_loop`: ``inner_process()`` first, then every
pending message in one batch (external ones to ``handle_msg``, internal ones to
``get_intra_msg_reply`` or ``store_intra_msg``), then ``inner_process()`` again,
until the robot cancels the task. Forwarding and reply matching happen when a
message is sent (see :mod:`cas_async._layer`), so this loop only sees messages for
its own layer.

Back-pressure: a send that fills another layer's inbox (see
:mod:`cas_async._channel`) marks the sender congested; after the hook that sent
it, the sender waits until that inbox drains to half its limit.
"""

from __future__ import annotations

from typing import Final

from ._layer import Layer
from ._message import MsgType

__all__ = ["run_loop"]

_NEGOTIATION: Final = MsgType.NEGOTIATION


async def run_loop(layer: Layer) -> None:
    """Thesis Fig. 10: inner process, then messages in batches, until cancelled."""
    robot = layer.robot
    inbox = layer._inbox
    pending = inbox._items  # read directly: Channel.__len__ is a call per check
    counters = layer._counters
    has_inner = type(layer).inner_process is not Layer.inner_process
    has_condition = layer._has_termination_condition()
    await layer.inner_process()
    if layer._congested is not None:
        await _wait_for_room(layer)
    if has_condition:
        robot._layer_may_be_done(layer)
    while True:
        if not pending:
            await inbox.wait()
        while pending:  # every message here is for this layer: forwarding is done
            msg = inbox.pop()
            if msg.src_layer == msg.dst_layer:
                counters.received_external += 1
                await layer.handle_msg(msg)
            else:
                counters.received_internal += 1
                if msg.msg_type == _NEGOTIATION and not msg.corr_id:
                    response = await layer.get_intra_msg_reply(msg)
                    if response is not None:
                        layer._reply_internal(robot, msg, response)
                else:
                    await layer.store_intra_msg(msg)
            if layer._congested is not None:
                await _wait_for_room(layer)
        if has_inner:
            await layer.inner_process()
            if layer._congested is not None:
                await _wait_for_room(layer)
        if has_condition:
            robot._layer_may_be_done(layer)


async def _wait_for_room(layer: Layer) -> None:
    """Waits while a layer that ``layer`` filled drains to half its limit.

    A layer never waits on one that waits, along a chain, on it: two layers
    flooding each other, or a consumer asking its producer, would wait forever.
    One of them goes on instead, which drains the other's sender. A layer that
    starts waiting on one held back by it releases it (``release_room_waiters``),
    so the check is made again.
    """
    target = layer._congested
    layer._congested = None
    assert target is not None
    while target._inbox.crowded and not _waits_on(target, layer):
        layer._waiting_on = target
        try:
            await target._inbox.room()
        finally:
            layer._waiting_on = None


def _waits_on(waiter: Layer, layer: Layer) -> bool:
    """Whether ``waiter`` waits, directly or along a chain, on ``layer``.

    A layer waits on another while it waits for room in its inbox, or for its
    answer to a request (then it handles nothing either).
    """
    along: Layer | None = waiter
    while along is not None:
        if along is layer:
            return True
        along = along._waiting_on
    return False
