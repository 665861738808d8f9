"""Scenario files (TOML under ``scenarios/``): schema, validation and typed access.

Entry point: :func:`swarm_common.scenario.model.load_scenario` returns a
:class:`~swarm_common.scenario.model.Scenario`.

* :mod:`.schema` - one frozen dataclass per TOML section; :mod:`.files` - reading and writing.
* :mod:`.checks` - checks across keys; :mod:`.feasibility` - can every vehicle fly its path.
* :mod:`.graphs` - neighbour graphs and their rigidity; :mod:`.spectra` - the eigenvalues
  and solves of their matrices.
"""
