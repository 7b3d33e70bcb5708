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
//
// Three kernels (xrayraster/recon/fdk_stream.py chooses): backproject, the general one (any
// geometry; GPUs, and CPUs without AVX2); backproject_windowed (x86 CPUs with AVX2 or AVX-512,
// upright detectors); backproject_columns (x86 CPUs with AVX-512, upright detectors: the default
// there). Upright (UPRIGHT): the detector's columns are parallel to the rotation axis, so a voxel
// column keeps one detector column and one weight per view (every circular orbit).

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

#if defined(TILE_VIEWS) && defined(cl_khr_fp64)
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
// backproject_columns, the CPU path with AVX-512 (built when the host defines TILE_VIEWS and the
// device has doubles). For an upright detector a voxel column along z keeps one detector column,
// one column fraction and one weight per view, and its rows are linear in z. A work-item owns a
// tile of 16 neighbouring voxel columns along x (one y) × 16 · GROUPS voxels along z (GROUPS
// vectors of 16, its sums: 4 KB), and takes the views in chunks of TILE_VIEWS:
//   1. per view of the chunk, the 16 columns' quantities as vectors over x (in double, see below):
//      detector column and fraction, weight, row step, each group's window start and offset;
//   2. per column of the tile, per view, per group of 16 voxels (column_window): four unaligned
//      vector loads (16-row windows of the two detector columns), interpolated between the
//      columns, two vpermt2ps for each lane's row and the next, one interpolation along the
//      column: ~20 instructions for 16 voxel updates.
// The chunk's views (~9 KB of each) stay in L1 while the tile's 16 columns pass over them, and
// the work-group's work-items pass over a block of TILE_BLOCK views together (a barrier after
// each), so they share the block in L2. The volume is read and written once a launch, 16
// neighbouring x at a time. Columns partly off the detector go group by group (groups wholly off
// it are skipped, those wholly on it take the window, the others window_sample16), as do voxels
// more than 29/15 detector rows tall, whose 16 rows the 32-row window cannot hold.
// Small work-groups only: PoCL keeps a work-group's private arrays (~7 KB a work-item) on its stack.
typedef int int16u __attribute__((ext_vector_type(16), aligned(4)));  // unaligned int16 stores

// A group's 16 voxels of one voxel column: lane l at row p + rel[l] of the detector column whose
// rows p points to (rel in [0, 30]), the column fraction fc towards the next. The two 16-row
// windows of both columns, interpolated between the columns, make the column's own line of the
// view; two vpermt2ps pick each lane's row and the next, and one linear interpolation along
// the column gives the sample.
__attribute__((always_inline)) inline float16 column_window(__global const float* p, int pitch, float16 rel, float fc) {
    const int16 k = __builtin_convertvector(rel, int16);
    const float16 a0 = *(__global const float16u*)p, a1 = *(__global const float16u*)(p + 16);
    const float16 b0 = *(__global const float16u*)(p + pitch), b1 = *(__global const float16u*)(p + pitch + 16);
    const float16 lo = a0 + fc * (b0 - a0), hi = a1 + fc * (b1 - a1);
    const float16 r0 = __builtin_ia32_vpermi2varps512(lo, k, hi), r1 = __builtin_ia32_vpermi2varps512(lo, k + 1, hi);
    return r0 + (rel - __builtin_convertvector(k, float16)) * (r1 - r0);  // rel − k: a rel rounded to just under 0 keeps row 0
}

__kernel void backproject_columns(__global float* restrict volume, __global const float* restrict filtered,
                                  __constant double* matrices, __constant float* scale,
                                  int views, int rows, int cols, int nx, int ny, int nz) {
    const int i0 = get_global_id(0) * 16, j = get_global_id(1), k0 = get_global_id(2) * (16 * GROUPS);
    const bool active = i0 < nx && j < ny && k0 < nz;  // every work-item reaches the barriers
    const int pitch = rows + 2;
    const size_t plane = (size_t)pitch * (cols + 2);
    const float col_end = (float)(cols + 1), row_end = (float)(rows + 1);
    const float16 lanes = LANES;
    const float16 x = (float)i0 + lanes;
    const double16 xd = __builtin_convertvector(x, double16);
    const double yd = (double)j, zd = (double)k0;
    const int16 in_volume = x < (float)nx;
    float16 sums[16][GROUPS];  // [column of the tile][group]: 16 voxels along z
    for (int t = 0; t < 16; ++t)
        for (int g = 0; g < GROUPS; ++g) sums[t][g] = 0.0f;
    // Per view of the chunk and column of the tile: where its detector column starts, the
    // fraction towards the next, the weight (0: off the detector, or past nx), the row step per
    // voxel, whether the fast path holds, and per group the first row of its window and the
    // offset of its first voxel's row from there.
    int offset[TILE_VIEWS][16], fast[TILE_VIEWS][16], start[TILE_VIEWS][GROUPS][16];
    float frac[TILE_VIEWS][16], weight[TILE_VIEWS][16], step[TILE_VIEWS][16], first[TILE_VIEWS][16];
    float skew[TILE_VIEWS][GROUPS][16];
    // Blocks of TILE_BLOCK views, a barrier after each: PoCL runs the whole work-group through a
    // block before the next, so its work-items share the block's views in L2.
    for (int block = 0; block < views; block += TILE_BLOCK) {
    for (int chunk = block; active && chunk < min(views, block + TILE_BLOCK); chunk += TILE_VIEWS) {
        const int count = min(TILE_VIEWS, views - chunk);
        for (int v = 0; v < count; ++v) {
            // The column and the first row in double, then as an integer and a float offset: the
            // fractions that weigh the samples keep float32's precision for small numbers (~1e-6 of
            // a pixel), not for numbers of the detector's size (3e-5 at 512 pixels, the other kernels').
            __constant double* m = matrices + 12 * (chunk + v);
            const double16 inv = 1.0 / (m[8] * xd + (m[9] * yd + m[11]));
            const double16 col = (m[0] * xd + (m[1] * yd + m[3])) * inv + 1.0;
            const double16 row0 = (m[4] * xd + (m[5] * yd + (m[6] * zd + m[7]))) * inv + 1.0;
            const float16 drow = __builtin_convertvector(m[6] * inv, float16);
            const int16 inside = in_volume & __builtin_convertvector((col >= 0.0) & (col < (double)col_end), int16);
            const int16 c = __builtin_convertvector(__builtin_convertvector(inside, long16) ? col : 0.0, int16);  // floor
            // The column's lowest row is its first voxel's (drow ≥ 0) or its last's, and so is each
            // group's; the window of 32 rows holds a group's rows and the next when 15·|drow| < 29.
            const float16 reach = drow * (float)(16 * GROUPS - 1), first_row = __builtin_convertvector(row0, float16);
            const float16 lowest = first_row + (drow < 0.0f ? reach : 0.0f), highest = first_row + (drow < 0.0f ? 0.0f : reach);
            const int16 ok = inside & (lowest >= 0.0f) & (highest < row_end) & ((drow < 0.0f ? -drow : drow) * 15.0f < 29.0f);
            // Rows from an integer anchor at or below every row of the column (where ok).
            const int16 anchor = __builtin_convertvector(ok ? lowest - 1.0f : 0.0f, int16);
            const float16 from_anchor = __builtin_convertvector(row0 - __builtin_convertvector(anchor, double16), float16);
            *(float16u*)frac[v] = __builtin_convertvector(col - __builtin_convertvector(c, double16), float16);
            *(float16u*)weight[v] = inside ? scale[chunk + v] * __builtin_convertvector(inv * inv, float16) : 0.0f;
            *(float16u*)step[v] = drow;
            *(float16u*)first[v] = first_row;
            *(int16u*)offset[v] = c * pitch;
            *(int16u*)fast[v] = ok;
            const float16 low = drow < 0.0f ? 15.0f * drow : 0.0f;
            #pragma unroll
            for (int g = 0; g < GROUPS; ++g) {
                const float16 base = from_anchor + (float)(16 * g) * drow;  // ≥ 0 where ok
                const int16 s = __builtin_convertvector(ok ? base + low : 0.0f, int16);  // floor where ok
                *(int16u*)start[v][g] = anchor + s;
                *(float16u*)skew[v][g] = base - __builtin_convertvector(s, float16);
            }
        }
        for (int t = 0; t < 16; ++t) {
            float16 acc[GROUPS];
            #pragma unroll
            for (int g = 0; g < GROUPS; ++g) acc[g] = sums[t][g];
            for (int v = 0; v < count; ++v) {
                const float w = weight[v][t];
                if (w == 0.0f) continue;
                __global const float* qc = filtered + (size_t)(chunk + v) * plane + offset[v][t];
                const float fc = frac[v][t];
                const float16 along = lanes * step[v][t];  // each lane's rows past its group's first voxel
                if (fast[v][t]) {
                    #pragma unroll
                    for (int g = 0; g < GROUPS; ++g)
                        acc[g] += w * column_window(qc + start[v][g][t], pitch, along + skew[v][g][t], fc);
                } else {  // some voxels off the detector, or far apart: group by group
                    const float row0 = first[v][t], drow = step[v][t];
                    const float low = drow < 0.0f ? 15.0f * drow : 0.0f, span = drow < 0.0f ? -15.0f * drow : 15.0f * drow;
                    #pragma unroll
                    for (int g = 0; g < GROUPS; ++g) {
                        const float base = row0 + (float)(16 * g) * drow, lowest = base + low, highest = lowest + span;
                        if (highest < 0.0f || lowest >= row_end) continue;  // the whole group off the detector
                        if (lowest >= 0.0f && highest < row_end && span < 29.0f) {
                            const int s = (int)lowest;
                            acc[g] += w * column_window(qc + s, pitch, along + (base - (float)s), fc);
                        } else {
                            acc[g] += w * window_sample16(qc, pitch, base + along, fc, row_end);
                        }
                    }
                }
            }
            #pragma unroll
            for (int g = 0; g < GROUPS; ++g) sums[t][g] = acc[g];
        }
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    }
    if (!active) return;
    const size_t sheet = (size_t)ny * nx;
    __global float* out = volume + (size_t)k0 * sheet + (size_t)j * nx + i0;
    const int width = min(16, nx - i0), depth = min(16 * GROUPS, nz - k0);
    for (int g = 0; g < GROUPS; ++g)
        for (int kk = 0; kk < 16 && 16 * g + kk < depth; ++kk)
            for (int t = 0; t < width; ++t) out[(size_t)(16 * g + kk) * sheet + t] += sums[t][g][kk];
}
#endif
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
