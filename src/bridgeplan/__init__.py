"""bridgeplan: planning with diffusion models and Schrödinger bridges from informative priors."""

__version__ = "0.1.0"
