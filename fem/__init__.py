"""FEM ground truth: tissue-shell tetrahedral meshes, Neo-Hookean material, Newton solver and
dataset generation. Arrives with the FEM issue; ``stmpl`` never imports it at module level."""
