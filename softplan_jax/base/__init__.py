"""The ground floor: what every layer above uses and nothing here imports from above.

* :mod:`.numerics` -- NaN-free norms, pseudo-inverses and masked evaluation;
* :mod:`.validation` -- the input checks behind every ``ValueError`` of the API;
* :mod:`.status` -- the rollout status codes;
* :mod:`.compilation_cache` -- compiled programs kept on disk;
* :mod:`.memory` -- the memory a request needs, checked before anything is allocated;
* :mod:`.files` -- output files written whole, with an ordinary file mode.
"""

__all__: list[str] = []
