"""Studies over many model runs: uncertainty (Monte Carlo / quasi-Monte Carlo) and Sobol sensitivity."""
