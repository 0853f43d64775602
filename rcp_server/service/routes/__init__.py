"""One router per surface: ``rest`` (``/api``) and ``walk`` (the ``/ws`` walk-through)."""
