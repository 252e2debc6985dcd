# Acrylic (PMMA): n_d 1.4914, Abbe number V_d 57.4 (Cauchy fit to n_d and V_d; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'ABBE'
opal.abbe_number = 57.4
opal.node_ior = 1.4914
