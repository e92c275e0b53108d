"""Design and tuning: the gains (c1, c2), their admissible set, noise, model error, switching on."""
