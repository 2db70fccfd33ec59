"""The ground floor: what every layer above uses and nothing here imports from above. NaN-free norms,
pseudo-inverses and masked evaluation (:mod:`._numerics`), the input checks behind every
``ValueError`` of the API (:mod:`._validation`), the rollout status codes (:mod:`._status`), compiled
programs kept on disk (:mod:`._compilation_cache`), the memory a request needs, checked before
anything is allocated (:mod:`._memory`), and output files written whole (:mod:`._files`)."""

__all__: list[str] = []
