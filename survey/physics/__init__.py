"""The model: interaction terms, their forces and tangent forces, the system's right-hand
side and energies, triangle geometry, Jacobi coordinates, initial-condition families and
equilibria. Compiled leaf kernels; imports the catalog and the machine layer."""
