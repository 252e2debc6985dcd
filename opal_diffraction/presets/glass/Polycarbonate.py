# Polycarbonate: n_d 1.585, Abbe number V_d 30 (Cauchy fit to n_d and V_d; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'ABBE'
opal.abbe_number = 30.0
opal.node_ior = 1.585
