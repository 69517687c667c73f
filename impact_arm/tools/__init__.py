"""User tools: the impact-arm CLI and its sub-commands (run, analyze, sweep, bench, ...)."""
