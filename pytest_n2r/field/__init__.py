"""Scene fields: the representation a scene file stores, and all of its sampling maths, written once.

- :mod:`~pytest_n2r.field.space`: the normalized, contracted scene space (the contraction's definition);
- :mod:`~pytest_n2r.field.grid`: the sparse voxel grid of density and colour (:class:`SceneField`);
- :mod:`~pytest_n2r.field.density`: the density's shift, set from an initial opacity, and the shifts a scene
  file holds;
- :mod:`~pytest_n2r.field.lattice`: where a ray is sampled, and the contraction and grid lookup in torch;
- :mod:`~pytest_n2r.field.kernels`: the same maths compiled (numba), and the marching kernels;
- :mod:`~pytest_n2r.field.march`: a ray batch's occupied samples, packed;
- :mod:`~pytest_n2r.field.query`: differentiable evaluation and compositing of packed samples (torch);
- :mod:`~pytest_n2r.field.config`: how a field is fitted: grid schedule, optimizer and regularization settings;
- :mod:`~pytest_n2r.field.device`: which torch device a fit or a scene uses.

Renderers (:mod:`pytest_n2r.render`) and fitting (:mod:`pytest_n2r.fit`) build on it; it imports neither.
"""
