"""Post-processing of a solution: fields, stresses, VTK/XDMF output, figures."""
