"""The benchmarks behind ``rcp bench``: they sit above the engine and the service and use their public API.

``speed`` (the engine against Embree alone), ``latency`` (the walk-through against a real server), ``soak``
(``rcp serve`` under load), ``accuracy`` and ``stability`` (both methods against a reference, charted), with
``metrics`` (PSNR, SSIM); ``cli`` adds their subcommands to ``rcp``. Their servers on loopback come from
``service/loopback.py``, which the tests share. A plain install runs speed, latency and soak; accuracy and
stability chart with matplotlib, from the ``bench`` extra.
"""
