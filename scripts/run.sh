#!/usr/bin/env bash
# SPDX-License-Identifier: Apache-2.0
# README command 1: install what is missing, build in Release, and run the main job:
# rasterize every scene in data/ into out/NAME.vdb (one summary line per scene), then the grid
# pipelines: the union, intersection and difference of two rasterized spheres as grid CSG, a
# grid blend, and the gradient and mean curvature of the difference of two spheres (data/fig1_difference);
# meshes of that difference coloured by its mean curvature (HSV over [-50, 50]) and of the
# blended union (data/fig5_blend_union), gradient arrows on a sphere, a Blender-ready --fog copy of the
# blended union, and the gallery (docs/gallery.md): the figures rendered into out/*.png (with
# data/knot_smooth.json, a mesh smooth-unioned with implicit shapes); and the animated metaballs
# (data/anim_metaballs.json) as a 48-frame sequence out/anim/metaballs_####.vdb that Blender
# plays, with a contact sheet of 8 frames coloured by mean curvature (out/anim_metaballs_sheet.png).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh
scripts/build.sh
ivdb=build/bin/ivdb
mkdir -p out
for scene in data/*.json; do
  case "$scene" in data/anim_*) continue ;; esac # sequences, below
  "$ivdb" rasterize "$scene" -o "out/$(basename "$scene" .json).vdb"
done
"$ivdb" rasterize data/inputs/sphere_left.json -o out/sphere_left.vdb -q
"$ivdb" rasterize data/inputs/sphere_right.json -o out/sphere_right.vdb -q
for op in union intersection difference; do
  "$ivdb" csg "$op" out/sphere_left.vdb out/sphere_right.vdb -o "out/grid_fig1_$op.vdb"
done
"$ivdb" blend union out/sphere_left.vdb out/sphere_right.vdb -p 50 -o out/grid_blend_union_p50.vdb
"$ivdb" gradient out/fig1_difference.vdb -o out/fig1_difference_gradient.vdb --magnitude --with-input
"$ivdb" curvature out/fig1_difference.vdb -o out/fig1_difference_curvature.vdb --with-input
"$ivdb" mesh out/fig1_difference.vdb -o out/fig1_difference_curvature.ply \
  --color-by out/fig1_difference_curvature.vdb:curvature --colormap hsv --range=-50,50
"$ivdb" mesh out/fig5_blend_union.vdb -o out/fig5_blend_union.obj
"$ivdb" rasterize data/fig5_blend_union.json -o out/fig5_blend_union_fog.vdb --fog -q
"$ivdb" gradient out/sphere.vdb -o out/sphere_gradient.vdb --with-input -q
"$ivdb" glyphs out/sphere_gradient.vdb -o out/fig3_sphere_arrows.ply --stride 8
# The gallery: the gallery's figures as images (README, docs/ holds 320x240 copies).
for f in fig1_union fig1_intersection fig1_difference fig2_plane fig2_cylinder fig2_ellipsoid \
         fig2_cone fig2_paraboloid fig2_hyperboloid fig5_blend_union knot_smooth; do
  "$ivdb" render "out/$f.vdb" -o "out/$f.png" -q
done
"$ivdb" render out/sphere.vdb -o out/fig3_sphere_gradient.png --color-by out/sphere_gradient.vdb -q
"$ivdb" render out/fig1_difference.vdb -o out/fig4_difference_curvature.png \
  --color-by out/fig1_difference_curvature.vdb:curvature --colormap hsv --range=-50,50 -q
# The animation: every frame, then the mean curvature of the 8 frames on the contact sheet.
mkdir -p out/anim
"$ivdb" rasterize data/anim_metaballs.json -o out/anim/metaballs_####.vdb
for f in 0001 0007 0013 0019 0025 0031 0037 0043; do
  "$ivdb" curvature "out/anim/metaballs_$f.vdb" -o "out/anim/curvature_$f.vdb" -q
done
"$ivdb" render out/anim/metaballs_####.vdb --frames 1-43:6 --columns 4 --size 320x240 \
  --color-by out/anim/curvature_####.vdb:curvature --colormap coolwarm --range=-2,2 \
  -o out/anim_metaballs_sheet.png
