# Flint Glass F2: n_d 1.62004, Abbe number V_d 36.37 (Cauchy fit to n_d and V_d; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'ABBE'
opal.abbe_number = 36.37
opal.node_ior = 1.62004
