"""The paper's deployment scenarios as reproducible experiments (``routing-svc paper``).

One module per experiment, each a pure ``run(*, seeds, quick, seed)`` that
returns an :class:`~routing_svc.paper.result.ExperimentResult`;
:mod:`routing_svc.paper.figures` draws it and :mod:`routing_svc.paper.command`
writes the JSON and the PNG. See ``docs/paper.md``.
"""
