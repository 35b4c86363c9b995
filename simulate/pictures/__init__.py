"""Pictures: family geometry as meshes, 3-D renders and animations, matplotlib plots, VTK export."""
