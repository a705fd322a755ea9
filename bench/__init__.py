"""jaxkin benchmarks (not part of the installed package); run them with ``python3 -m bench``.

See bench/README.md for the method and the latest measured table.
"""
