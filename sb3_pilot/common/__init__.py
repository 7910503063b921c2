"""What the three stages share: Gaussian log-likelihoods, argument checks and small torch helpers."""
