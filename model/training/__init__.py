"""Training: the command's settings (``config``: ``TrainConfig``), the loop (``loop``), the
paper's and the referent path's steps (``referent_step``; ``referent_cache``: the
``--freeze-scene`` stage on scenes encoded once), the roots of a run (``data``), the one atomic
run state (``state``), SIGINT / SIGTERM (``stop_signal``), torchrun and DDP (``distributed``) and
the choice of the operating threshold (``calibrate``)."""
