"""Maps and local theory: the Poincare maps, the model protocol, the discontinuity maps, perturbation estimates."""
