"""Free planar rigid bodies (x, z, θ) with rounded corners striking surfaces at any angle:
the scene section (``scene``), the compiled stepping (``kernel``), the model and its runs
(``model``) and the rigid-body impact laws it is compared with (``impulse``)."""

# its modules are imported by name: the package itself exports none
__all__: list[str] = []
