"""Jack/TTES clients, one package per application: ``link`` (the one server connection), ``stub``
(pyrender), ``dis`` (DIS replay and gateway), ``loadtest``, ``crowd`` (moderngl). Never imports ``server``."""
