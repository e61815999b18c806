"""Learnable Contracts (they need the rl extra; the probes and the app do not)."""

from cas_async.rl import PolicyLayer
from contract_net.app import Contract
from contract_net.probes import LazyContract


class LearnedContract(PolicyLayer, Contract):
    """The policy scales this robot's bids (action 0: honest, 1: doubled)."""

    def cost(self, distance: float) -> float:
        return distance * (1.0 + float(self.decide(distance)))


class LazyLearned(PolicyLayer, LazyContract):
    """The lazy contract as a policy layer (it never decides)."""
