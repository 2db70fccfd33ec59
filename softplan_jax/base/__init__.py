"""The ground floor: what every layer above uses and nothing here imports from above.

* :mod:`.numerics` -- NaN-free norms, pseudo-inverses and masked evaluation;
* :mod:`.validation` -- the input checks behind every ``ValueError`` of the API;
* :mod:`.status` -- the rollout status codes;
* :mod:`.compilation_cache` -- compiled programs kept on disk.
"""

__all__: list[str] = []
