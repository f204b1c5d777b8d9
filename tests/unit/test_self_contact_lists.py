"""The pairs a self-contact step corrects do not depend on which valid candidate list holds
them: a list built now and one built earlier (before a tangential slide, with a wider skin)
give the same step bit for bit, pairs in the tolerance band above the contact distance
included. This is what lets a resumed run, which builds a fresh list, repeat the
uninterrupted one."""

import numpy as np
from mpi4py import MPI

from clothfem import mesh as meshes
from clothfem.contact.self_contact import (
    SelfContactParameters,
    build_candidates,
    fabric_surface,
    mesh_nodes,
    self_contact_step,
)


def test_step_is_the_same_with_any_valid_list():
    X, cells = mesh_nodes(meshes.strip(MPI.COMM_SELF, length=0.1, width=0.1, nx=4, ny=4).mesh)
    n, d = len(X), 1e-3
    p = SelfContactParameters(distance=d, mu=0.3)
    rng = np.random.default_rng(3)
    top = X + np.column_stack([np.zeros((n, 2)), rng.uniform(0.995 * d, 1.009 * d, n)])
    x0 = np.vstack([X, top])
    surface = fabric_surface(np.vstack([cells, cells + n]), n_nodes=2 * n)
    v = np.zeros_like(x0)
    v[n:] = [0.02, 0.0, -0.01]  # the top sheet slides and presses
    dt = 1e-4
    xs = x0 + dt * v
    mass = np.full(2 * n, 1e-5)
    reach = d * (1 + p.tolerance)
    fresh = build_candidates(xs, surface, distance=reach, skin=p.skin_length)
    earlier = x0.copy()
    earlier[n:, 0] -= 0.5 * d  # the top sheet half a contact distance back
    old = build_candidates(earlier, surface, distance=reach, skin=5 * d)
    assert old.valid(x0, xs) and fresh.valid(x0, xs)
    runs = [
        self_contact_step(x0, xs, v, mass, dt, surface, params=p, candidates=c)
        for c in (fresh, old)
    ]
    gaps = runs[0].contacts.gap
    assert np.any(gaps < d) and np.any((gaps >= d) & (gaps < reach))  # both kinds present
    assert np.array_equal(runs[0].x, runs[1].x) and np.array_equal(runs[0].v, runs[1].v)
    assert np.array_equal(runs[0].jn, runs[1].jn)
