"""Offline data shared by every environment family: the in-memory :class:`~bridgeplan.data.stream.Stream` (continuous
segments of state-action pairs) and the training windows cut from it (:mod:`~bridgeplan.data.windows`). Each family
reads and writes its own files (:mod:`bridgeplan.envs`)."""
