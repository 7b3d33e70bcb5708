// FDK stage 2: voxel-driven backprojection with bilinear interpolation (xrayraster/recon/fdk.py).
//
// Layout of the filtered projections: (views, rows + 2, cols + 2) by default (GPUs: neighbouring
// work-items read neighbouring columns of one row, coalesced); with COLUMN_MAJOR, (views,
// cols + 2, rows + 2) (CPUs: a work-item's ZCHUNK voxels read a short contiguous run of rows,
// a few cache lines per view instead of one per row).
//
// A work-item owns ZCHUNK voxels of one (x, y) column and keeps their sums in registers over a
// batch of views, then adds them to the volume once. Per view, the voxel's detector position
// comes from the view's 3×4 matrix: (col·w, row·w, w) = P·(i, j, k, 1); along the column only k
// changes, so each step adds P's third column. The filtered projections carry a one-pixel ring
// of zeros, so a sample anywhere in [−1, cols] × [−1, rows] needs no further bounds checks
// (neighbours outside the detector count as zero).

#ifndef ZCHUNK
#define ZCHUNK 8
#endif

#ifdef COLUMN_MAJOR
#define ROW_STEP 1
#define COL_STEP (rows + 2)
#else
#define ROW_STEP (cols + 2)
#define COL_STEP 1
#endif

// Bilinear sample at pixel p (the lower-left of the four) with fractions fc, fr.
__attribute__((always_inline)) inline float bilinear(__global const float* p, float fc, float fr, int rows, int cols) {
    const float low = p[0] + fc * (p[COL_STEP] - p[0]);
    const float high = p[ROW_STEP] + fc * (p[ROW_STEP + COL_STEP] - p[ROW_STEP]);
    return low + fr * (high - low);
}

__kernel void backproject(__global float* restrict volume,          // (nz, ny, nx) slab, accumulated into
                          __global const float* restrict filtered,  // (views, rows + 2, cols + 2), or COLUMN_MAJOR
                          __constant float* matrices,      // (views, 12): P row-major, slab voxel indices
                          __constant float* scale,         // (views,): Δθ·R/D or Δθ
                          int views, int rows, int cols, int nx, int ny, int nz) {
    const int i = get_global_id(0), j = get_global_id(1), k0 = get_global_id(2) * ZCHUNK;
    if (i >= nx || j >= ny || k0 >= nz) return;
    const size_t plane = (size_t)(rows + 2) * (cols + 2);
    const float col_end = (float)(cols + 1), row_end = (float)(rows + 1);
    float acc[ZCHUNK];
    #pragma unroll
    for (int kk = 0; kk < ZCHUNK; ++kk) acc[kk] = 0.0f;

    for (int view = 0; view < views; ++view) {
        __constant float* m = matrices + 12 * view;
        // +1 in col and row: index 0 of the filtered rows is the zero ring.
        const float a0 = m[0] * i + m[1] * j + m[2] * k0 + m[3];
        const float b0 = m[4] * i + m[5] * j + m[6] * k0 + m[7];
        const float w0 = m[8] * i + m[9] * j + m[10] * k0 + m[11];
        const float s = scale[view];
        __global const float* q = filtered + view * plane;
#ifdef UPRIGHT
        // Detector columns parallel to z (every circular scan): the column and the distance
        // weight are the same all along the voxel column; only the row moves, linearly.
        const float inv = 1.0f / w0;
        const float col = a0 * inv + 1.0f;
        if (col < 0.0f || col >= col_end) continue;
        const int c = (int)col;
        const float fc = col - c;
        const float weight = s * inv * inv;
        const float row0 = b0 * inv + 1.0f, drow = m[6] * inv;
        __global const float* qc = q + c * COL_STEP;
        #pragma unroll
        for (int kk = 0; kk < ZCHUNK; ++kk) {
            const float row = row0 + kk * drow;
            if (row >= 0.0f && row < row_end) {
                const int r = (int)row;
                acc[kk] += weight * bilinear(qc + r * ROW_STEP, fc, row - r, rows, cols);
            }
        }
#else
        #pragma unroll
        for (int kk = 0; kk < ZCHUNK; ++kk) {
            const float w = w0 + kk * m[10];
            const float inv = 1.0f / w;
            const float col = (a0 + kk * m[2]) * inv + 1.0f;
            const float row = (b0 + kk * m[6]) * inv + 1.0f;
            if (col >= 0.0f && col < col_end && row >= 0.0f && row < row_end) {
                const int c = (int)col, r = (int)row;
                acc[kk] += s * inv * inv * bilinear(q + r * ROW_STEP + c * COL_STEP, col - c, row - r, rows, cols);
            }
        }
#endif
    }
    for (int kk = 0; kk < ZCHUNK && k0 + kk < nz; ++kk) volume[((size_t)(k0 + kk) * ny + j) * nx + i] += acc[kk];
}

// Built when the host defines WIDTH (8 or 16) and GROUPS.
#if defined(UPRIGHT) && defined(COLUMN_MAJOR) && defined(GROUPS) && defined(__AVX2__) && \
    (WIDTH == 8 || (WIDTH == 16 && defined(__AVX512F__)))
// The CPU path (x86 with AVX2, e.g. PoCL) for upright detectors and column-major views. A
// work-item owns WIDTH × GROUPS voxels of a z column as GROUPS vectors of WIDTH floats: 8 with
// AVX2, 16 with AVX-512 (the host asks for 16 first). Per view, the rows of a vector's voxels lie
// in a short run of the two detector columns around the voxel's column: a few contiguous vector
// loads and permutes spread them to the lanes, instead of 4 × WIDTH scalar loads. Runs longer
// than the loads hold (voxels much coarser than the pixels) take the scalar path. Only operators
// and clang vector builtins appear here: PoCL calls OpenCL builtins (vload8, select, shuffle2,
// clamp...) as out-of-line functions, which undoes the vectors.
// The host pads the filtered buffer so a window may read past the last column.
typedef float float8u __attribute__((ext_vector_type(8), aligned(4)));  // unaligned float8 loads

__attribute__((always_inline)) inline float8 pick(float8 low, float8 high, int8 k) {
    return (k < 8) ? __builtin_ia32_permvarsf256(low, k) : __builtin_ia32_permvarsf256(high, k);
}

__attribute__((always_inline)) inline float8 window_sample(__global const float* qc, int pitch, float8 row, float fc,
                                                           float row_end) {
    // Fast path, the usual case (voxels no coarser than the magnified pixels, all 8 rows on the
    // detector): the rows' floors span at most 8, so one load at the first row and one a row
    // later give both bilinear neighbours of every lane with a single permute each.
    const float row_min = row.s0 < row.s7 ? row.s0 : row.s7, row_max = row.s0 < row.s7 ? row.s7 : row.s0;
    // The lanes' pixel rows (floors) must lie within 8 of the first: spans up to 8 rows, as
    // voxels of the magnified pixel size give (7 row steps of about 1), qualify.
    if (row_min >= 0.0f && row_max < row_end && (int)row_max - (int)row_min < 8) {
        const int8 r = __builtin_convertvector(row, int8);  // floor: row ≥ 0
        const int start = (int)row_min;
        const int8 k = r - start;
        const float8 p00 = __builtin_ia32_permvarsf256(*(__global const float8u*)(qc + start), k);
        const float8 p10 = __builtin_ia32_permvarsf256(*(__global const float8u*)(qc + start + 1), k);
        const float8 p01 = __builtin_ia32_permvarsf256(*(__global const float8u*)(qc + pitch + start), k);
        const float8 p11 = __builtin_ia32_permvarsf256(*(__global const float8u*)(qc + pitch + start + 1), k);
        const float8 low = p00 + fc * (p01 - p00), high = p10 + fc * (p11 - p10);
        return low + (row - __builtin_convertvector(r, float8)) * (high - low);
    }
    const int8 inside = (row >= 0.0f) & (row < row_end);
    const float8 rowc = (row < 0.0f) ? 0.0f : ((row > row_end) ? row_end : row);  // monotone along the lanes
    const int8 r = __builtin_convertvector(rowc, int8);  // floor: rowc ≥ 0
    const int first = r.s0, last = r.s7;
    const int start = first < last ? first : last;
    const int span = first < last ? last - first : first - last;
    float8 value;
    if (span < 15) {
        const int8 k = r - start;
        const float8 a0 = *(__global const float8u*)(qc + start), a1 = *(__global const float8u*)(qc + start + 8);
        const float8 b0 = *(__global const float8u*)(qc + pitch + start);
        const float8 b1 = *(__global const float8u*)(qc + pitch + start + 8);
        const float8 p00 = pick(a0, a1, k), p10 = pick(a0, a1, k + 1);
        const float8 p01 = pick(b0, b1, k), p11 = pick(b0, b1, k + 1);
        const float8 low = p00 + fc * (p01 - p00), high = p10 + fc * (p11 - p10);
        value = low + (rowc - __builtin_convertvector(r, float8)) * (high - low);
    } else {
        float lanes[8];
        *(float8u*)lanes = rowc;
        for (int kk = 0; kk < 8; ++kk) {
            const int rr = (int)lanes[kk];
            lanes[kk] = bilinear(qc + rr, fc, lanes[kk] - rr, pitch - 2, 0);  // (rows, cols): only rows is read
        }
        value = *(float8u*)lanes;
    }
    return inside ? value : 0.0f;
}

#if WIDTH == 16
typedef float float16u __attribute__((ext_vector_type(16), aligned(4)));  // unaligned float16 loads
typedef float16 floatw;
typedef float16u floatwu;

// 16 voxels: two loads of 16 rows per detector column hold a window of 32 rows, and vpermt2ps
// picks each lane's pixel and the one below from it: spans of up to 30 rows, so voxels up to
// twice the magnified pixel take this path. Else each half takes window_sample's.
__attribute__((always_inline)) inline float16 window_sample16(__global const float* qc, int pitch, float16 row,
                                                              float fc, float row_end) {
    const float row_min = row.s0 < row.sf ? row.s0 : row.sf, row_max = row.s0 < row.sf ? row.sf : row.s0;
    if (row_min >= 0.0f && row_max < row_end && (int)row_max - (int)row_min < 31) {
        const int16 r = __builtin_convertvector(row, int16);  // floor: row ≥ 0
        const int start = (int)row_min;
        const int16 k = r - start;
        const float16 a0 = *(__global const float16u*)(qc + start), a1 = *(__global const float16u*)(qc + start + 16);
        const float16 b0 = *(__global const float16u*)(qc + pitch + start);
        const float16 b1 = *(__global const float16u*)(qc + pitch + start + 16);
        const float16 p00 = __builtin_ia32_vpermi2varps512(a0, k, a1), p10 = __builtin_ia32_vpermi2varps512(a0, k + 1, a1);
        const float16 p01 = __builtin_ia32_vpermi2varps512(b0, k, b1), p11 = __builtin_ia32_vpermi2varps512(b0, k + 1, b1);
        const float16 low = p00 + fc * (p01 - p00), high = p10 + fc * (p11 - p10);
        return low + (row - __builtin_convertvector(r, float16)) * (high - low);
    }
    float16 value;
    value.lo = window_sample(qc, pitch, row.lo, fc, row_end);
    value.hi = window_sample(qc, pitch, row.hi, fc, row_end);
    return value;
}
#define WINDOW_SAMPLE window_sample16
#define LANES (float16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15)
#else
typedef float8 floatw;
typedef float8u floatwu;
#define WINDOW_SAMPLE window_sample
#define LANES (float8)(0, 1, 2, 3, 4, 5, 6, 7)
#endif

__kernel void backproject_windowed(__global float* restrict volume, __global const float* restrict filtered,
                                   __constant float* matrices, __constant float* scale,
                                   int views, int rows, int cols, int nx, int ny, int nz) {
    const int i = get_global_id(0), j = get_global_id(1), k0 = get_global_id(2) * (WIDTH * GROUPS);
    if (i >= nx || j >= ny || k0 >= nz) return;
    const int pitch = rows + 2;
    const size_t plane = (size_t)pitch * (cols + 2);
    const float col_end = (float)(cols + 1), row_end = (float)(rows + 1);
    floatw acc[GROUPS];
    for (int g = 0; g < GROUPS; ++g) acc[g] = 0.0f;
    for (int view = 0; view < views; ++view) {
        __constant float* m = matrices + 12 * view;
        const float inv = 1.0f / (m[8] * i + m[9] * j + m[11]);
        const float col = (m[0] * i + m[1] * j + m[3]) * inv + 1.0f;
        if (col < 0.0f || col >= col_end) continue;
        const int c = (int)col;
        const float weight = scale[view] * inv * inv;
        const float drow = m[6] * inv;
        const floatw row = (m[4] * i + m[5] * j + m[6] * k0 + m[7]) * inv + 1.0f + LANES * drow;
        __global const float* qc = filtered + view * plane + (size_t)c * pitch;
        #pragma unroll
        for (int g = 0; g < GROUPS; ++g)
            acc[g] += weight * WINDOW_SAMPLE(qc, pitch, row + ((float)WIDTH * g) * drow, col - c, row_end);
    }
    float out[WIDTH * GROUPS];
    for (int g = 0; g < GROUPS; ++g) *(floatwu*)(out + WIDTH * g) = acc[g];
    for (int kk = 0; kk < WIDTH * GROUPS && k0 + kk < nz; ++kk) volume[((size_t)(k0 + kk) * ny + j) * nx + i] += out[kk];
}
#endif
