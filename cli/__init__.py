"""The ``tetc`` command-line front end (installed as ``gatun_py.cli``)."""
