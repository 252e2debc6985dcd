# Fused Silica: n_d 1.4585, Abbe number V_d 67.82 (Sellmeier data; docs/physics.md section 2).
import bpy
opal = bpy.context.material.opal

opal.dispersion = 'FUSED_SILICA'
opal.abbe_number = 67.82
opal.node_ior = 1.4585
