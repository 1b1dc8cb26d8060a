"""The plugin's own tests. The plugin itself is loaded through its pytest11 entry point, as in a
user's suite (`pip install ./python/vtol_twin`); pytester runs inner sessions."""

pytest_plugins = ["pytester"]
