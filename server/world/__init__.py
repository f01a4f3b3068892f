"""The parts of one server's simulation, composed by :class:`server.startup.ServerWorld`.

* :mod:`~server.world.store` — :class:`MotionStore`: environment, channelsets, posture graphs, what is bound;
* :mod:`~server.world.library` — the motion library built from the loaded and bound graphs (seed 3.6);
* :mod:`~server.world.soldiers` — :class:`Soldiers`: the soldier manager, its settings, a wire table per set;
* :mod:`~server.world.commands` — the JCL commands of seed 3.4-3.6, a thin typed adapter over the above;
* :mod:`~server.world.synthetic` — a synthetic data directory for tests and benches.
"""
