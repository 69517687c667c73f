"""User tools: the impact-arm CLI and its sub-commands (run, analyze, sweep, bench, ...)."""

# its modules are imported by name: the package itself exports none
__all__: list[str] = []
