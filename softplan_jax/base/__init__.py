"""The ground floor: what every layer above uses and nothing here imports from above. NaN-free norms,
pseudo-inverses and masked evaluation (:mod:`.numerics`), the input checks behind every
``ValueError`` of the API (:mod:`.validation`), the rollout status codes (:mod:`.status`), compiled
programs kept on disk (:mod:`.compilation_cache`), the memory a request needs, checked before
anything is allocated (:mod:`.memory`), and output files written whole (:mod:`.files`)."""

__all__: list[str] = []
