"""``rozyn bench``: the core's speed figures (``command``) and the node under load over DDS
(``nodes``, ``rozyn bench --nodes``), as JSON."""
