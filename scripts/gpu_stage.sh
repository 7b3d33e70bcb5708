#!/bin/bash
# Stage what scripts/gpu_check.sh needs on a bare GPU machine (Python 3.12, no network) into the
# repository's ignored .whl/ and .gl/. Run in the repository root: ~20 MB of wheels, 22.5 MB
# spekpy_w.zip (SpekPy cut to its tungsten tables), 0.23 MB of GL loader packages. The versions are
# those this project was last tested with: check `pip list`.
set -e
P="--no-deps --only-binary=:all: --python-version 3.12 --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --platform manylinux1_x86_64"
mkdir -p .whl .gl /tmp/amd64/partial /tmp/spek
python3 -m pip download $P -d .whl moderngl==5.13.0 glcontext==3.1.0 trimesh==5.2.0 manifold3d==3.5.4 tomli_w==1.2.0 \
  xraylib==4.3.0 pyopencl==2026.1.4 pytools==2026.1.1 siphash24==1.9 platformdirs==4.14.8
python3 -m pip download $P -d /tmp/spek spekpy==2.5.4
python3 - <<'PY'   # SpekPy without KQP.npz and the Cu/Mo/Rh anodes' tables; W tables Z74_1..9 (kVp < 125)
import glob, re, zipfile
src = zipfile.ZipFile(glob.glob('/tmp/spek/spekpy-*.whl')[0])
with zipfile.ZipFile('.whl/spekpy_w.zip', 'w', zipfile.ZIP_DEFLATED, compresslevel=9) as out:
    for i in src.infolist():
        m = re.search(r'advanced/(?:Z|FluorescenceZ|MassAttCoeff_Z)(\d+)(?:_(\d+))?', i.filename)
        if i.filename.endswith('KQP.npz') or (m and (m.group(1) != '74' or int(m.group(2) or 0) > 9)):
            continue
        out.writestr(i, src.read(i.filename))
PY
o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
apt-get $o update -qq; (cd .gl && apt-get $o download libegl1 libglvnd0 libopengl0 libgl1 libglx0)
du -ch .whl .gl | tail -1
