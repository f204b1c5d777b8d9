#!/usr/bin/env bash
# Idempotent set-up of a fresh Debian 12 machine for clothfem:
#   1. Debian's FEniCSx stack (dolfinx 0.5.2, PETSc 3.18) and OpenBLAS for MUMPS,
#   2. a .venv on /usr/bin/python3 with --system-site-packages,
#   3. clothfem (editable) and its dev tools, with numpy pinned to the system's version.
# A second run does nothing but checks.
set -euo pipefail
cd "$(dirname "$0")/.."

# gcc: dolfinx's form compiler and clothfem's contact loop (clothfem/contact/compiled.py)
# compile C at run time; python3-numba compiles the self-contact loops (NumPy fallback without
# it), python3-rich draws the progress bar on a terminal (plain lines without it)
APT_PKGS=(python3-dolfinx python3-gmsh python3-meshio python3-mpi4py python3-petsc4py
          python3-ufl python3-scipy python3-venv libopenblas0-pthread gcc
          python3-numba python3-rich)

missing=()
for p in "${APT_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "bootstrap: installing Debian packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# MUMPS is 2-5x faster on OpenBLAS than on the reference BLAS Debian may select.
blas=$(update-alternatives --query libblas.so.3-x86_64-linux-gnu 2>/dev/null | awk '/^Value:/{print $2}')
case "$blas" in
  *openblas*) ;;
  *) echo "bootstrap: selecting OpenBLAS for libblas.so.3"
     SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
     $SUDO update-alternatives --set libblas.so.3-x86_64-linux-gnu \
       /usr/lib/x86_64-linux-gnu/openblas-pthread/libblas.so.3 || true
     $SUDO update-alternatives --set liblapack.so.3-x86_64-linux-gnu \
       /usr/lib/x86_64-linux-gnu/openblas-pthread/liblapack.so.3 || true ;;
esac

if [ ! -x .venv/bin/python ]; then
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
# numpy 2 in the venv would break petsc4py ("numpy.dtype size changed"): pin the system's.
/usr/bin/python3 -c 'import numpy; print(f"numpy=={numpy.__version__}")' > .venv/constraints.txt
stamp=.venv/.clothfem-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  .venv/bin/pip install -q --disable-pip-version-check -c .venv/constraints.txt -e ".[dev]"
  touch "$stamp"
fi
.venv/bin/python -c "import dolfinx, petsc4py, clothfem" \
  || { echo "bootstrap: the environment does not import dolfinx/petsc4py/clothfem"; exit 1; }
