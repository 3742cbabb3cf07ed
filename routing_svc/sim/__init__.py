"""SUMO co-simulation: SUMO makes the demand, the fleet service positions and dispatches the fleet.

::

    run_cosim(CosimSpec(network="drt", vehicles=10, seeds=(0, 1, 2)), out_dir=...)
        spec.py       CosimSpec: what to simulate
        prepare.py    background traffic (randomTrips), requests, starts, optimum
        run.py        one policy in one SUMO process -> PolicyRun (waits from SUMO)
        dispatcher.py reservations -> fleet service's dispatch -> dispatchTaxi; vehicle
                      states back to the service; the queue; park at reference
        backend.py    SimBackend: LibsumoBackend (lazy libsumo), TraciBackend (GUI)
        measures.py   SUMO's tripinfo/personinfo -> waits, service levels, empty km, load
    write_figures(result, out_dir=..., prefix=...)  (plots.py)

``routing-svc cosim`` (:mod:`routing_svc.sim.command`) is the command line.
Nothing here imports libsumo at import time.
"""

from routing_svc.sim.backend import LibsumoBackend, SimBackend, SimulationError, TraciBackend
from routing_svc.sim.experiment import CosimResult, CosimSpec, run_cosim
from routing_svc.sim.measures import PolicyRun
from routing_svc.sim.policies import POLICIES, Policy, parse_policies
from routing_svc.sim.run import PolicyJob, run_policy

__all__ = [
    "POLICIES",
    "CosimResult",
    "CosimSpec",
    "LibsumoBackend",
    "Policy",
    "PolicyJob",
    "PolicyRun",
    "SimBackend",
    "SimulationError",
    "TraciBackend",
    "parse_policies",
    "run_cosim",
    "run_policy",
]
