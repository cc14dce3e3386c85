"""Bursts as tasks on a cluster of Dask's ``distributed`` engine (``lburst[cluster]``).

:mod:`~lburst.cluster.spec` reads ``--cluster`` (``local:N`` or a scheduler's address),
:mod:`~lburst.cluster.session` starts or joins the cluster, :mod:`~lburst.cluster.runner` maps a
per-burst function over jobs in this process or on the cluster (with a progress bar over
finished tasks), and :mod:`~lburst.cluster.models` keeps one extractor per worker process.
docs/large_surveys.md says how to start a cluster and what it costs.
"""
