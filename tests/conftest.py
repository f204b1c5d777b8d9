"""Ending a test run under mpirun.

After the last test, PETSc's finalization (petsc4py's exit handler) runs
``PetscGarbageCleanup``, a collective step over the objects whose destruction was deferred.
Python's garbage collector frees petsc4py objects at different moments on different ranks
(a rank that did more Python work, e.g. the donning run on rank 0 only, collects at other
times), and with the whole suite in one process the ranks can reach that cleanup with
different garbage: rank 0 then waits in ``MPI_Comm_dup`` for a rank that has already left,
and the run never ends although every test has passed. So on more than one rank the run
ends here instead: all ranks meet, MPI is finalized, and the process exits with pytest's
status without running PETSc's finalization (nothing is left to write). Serial runs end
normally.
"""

import os
import sys

from mpi4py import MPI

_STATUS = {"code": 3}  # pytest's internal-error status until the run reports its own


def pytest_terminal_summary(exitstatus):
    _STATUS["code"] = int(exitstatus)


def pytest_unconfigure(config):
    comm = MPI.COMM_WORLD
    if comm.size == 1:
        return
    sys.stdout.flush()
    sys.stderr.flush()
    code = comm.allreduce(_STATUS["code"], op=MPI.MAX)
    comm.Barrier()
    MPI.Finalize()
    os._exit(code)
