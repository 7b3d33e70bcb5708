// FDK stage 1: pre-weight, zero-pad and ramp-filter detector rows (xrayraster/recon/fdk.py).
//
// One work-group filters two rows at once: they go in as the real and imaginary parts of one
// complex FFT. The ramp response is real and even, so the filtered rows come back separated
// in the real and imaginary parts. Forward FFT: decimation in frequency (natural order in,
// bit-reversed out); the response is stored bit-reversed; inverse FFT: decimation in time
// (bit-reversed in, natural out). No reordering pass is needed.
//
// BUF is __local (the row pair lives in local memory) unless the padded row does not fit
// there, in which case the host builds with -DBUF=__global and passes scratch space.

#ifndef BUF
#define BUF __local
#endif

inline float2 cmul(float2 a, float2 b) { return (float2)(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x); }

// Pre-weight of pixel (row, col): redundancy × cosine weight ŝ·(p − s) / |p − s| (1 for parallel
// beams; xrayraster/recon/fdk_weights.py). geo holds per view: s, d, u, v (mm) and ŝ, the unit
// vector from the source towards the axis, each xyz 0.
inline float pre_weight(__global const float4* geo, __global const float* redundancy, int view, int row, int col,
                        int rows, int cols, int cone) {
    float w = redundancy[view * cols + col];
    if (cone) {
        __global const float4* g = geo + 5 * view;
        float3 ray = g[1].xyz + (col - 0.5f * (cols - 1)) * g[2].xyz + (row - 0.5f * (rows - 1)) * g[3].xyz - g[0].xyz;
        w *= dot(ray, g[4].xyz) / length(ray);
    }
    return w;
}

// Pre-weighted value of a row at column c (−pad ≤ c < cols + pad): the detector's pixel, or past an
// edge the host's extrapolation of it (xrayraster/recon/truncation.py: zeros where the row end is
// not extrapolated), else 0.
inline float row_value(__global const float* in, __global const float4* geo, __global const float* redundancy,
                       __global const float* extension, int view, int row, int c, int rows, int cols, int cone,
                       int pad) {
    if (c >= 0 && c < cols) return in[c] * pre_weight(geo, redundancy, view, row, c, rows, cols, cone);
    const int j = c < 0 ? -c : c - cols + 1;  // columns past the edge
    if (j > pad) return 0.0f;
    return extension[(((size_t)view * rows + row) * 2 + (c < 0 ? 0 : 1)) * pad + j - 1];
}

__kernel void filter_rows(__global const float* projections,  // (views, rows, cols) line integrals
                          __global float* filtered,           // (views, rows + 2, out_cols + 2) or COLUMN_MAJOR; ring kept zero
                          __global const float* redundancy,   // (views, cols)
                          __global const float4* geo,         // (views, 4) see pre_weight
                          __global const float* extension,    // (views, rows, 2, pad): past column 0, past the last
                          __global const float* response,     // (n) bit-reversed, 1/n included
                          __global const float2* twiddle,     // (n/2) exp(−2πik/n)
                          BUF float2* scratch,                // n per work-group (local) or per pair (global)
                          int rows, int cols, int lead, int out_cols, int pad, int n, int cone) {
    // Row pixel c sits at c + lead of the padded row (circularly: the columns extrapolated before
    // column 0 wrap to its end), and the output keeps out_cols of it from 0: the detector's columns
    // and the virtual ones around them (FDKViews.lead, trail). n ≥ 2·(out_cols + 2·pad).
    const int pair = get_group_id(0);
    const int pairs_per_view = (rows + 1) / 2;
    const int view = pair / pairs_per_view;
    const int r0 = 2 * (pair % pairs_per_view);
    const int r1 = r0 + 1;
    const int lid = get_local_id(0), lsize = get_local_size(0);
#ifdef GLOBAL_SCRATCH
    BUF float2* buf = scratch + (size_t)pair * n;
#else
    BUF float2* buf = scratch;
#endif
    __global const float* in0 = projections + ((size_t)view * rows + r0) * cols;
    for (int k = lid; k < n; k += lsize) {
        int c = k - lead;
        if (c >= n - lead - pad) c -= n;
        float2 x;
        x.x = row_value(in0, geo, redundancy, extension, view, r0, c, rows, cols, cone, pad);
        x.y = r1 < rows ? row_value(in0 + cols, geo, redundancy, extension, view, r1, c, rows, cols, cone, pad) : 0.0f;
        buf[k] = x;
    }
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);

    const int halfn = n / 2;
    for (int span = halfn; span >= 1; span >>= 1) {  // forward, decimation in frequency
        const int stride = halfn / span;
        for (int j = lid; j < halfn; j += lsize) {
            const int idx = j & (span - 1);
            const int a = ((j - idx) << 1) + idx, b = a + span;
            const float2 x = buf[a], y = buf[b];
            buf[a] = x + y;
            buf[b] = cmul(x - y, twiddle[idx * stride]);
        }
        barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    }
    for (int k = lid; k < n; k += lsize) buf[k] *= response[k];
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    for (int span = 1; span < n; span <<= 1) {  // inverse, decimation in time
        const int stride = halfn / span;
        for (int j = lid; j < halfn; j += lsize) {
            const int idx = j & (span - 1);
            const int a = ((j - idx) << 1) + idx, b = a + span;
            const float2 t = twiddle[idx * stride];
            const float2 y = cmul(buf[b], (float2)(t.x, -t.y));
            const float2 x = buf[a];
            buf[a] = x + y;
            buf[b] = x - y;
        }
        barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    }

#ifdef COLUMN_MAJOR
    const int row_step = 1, col_step = rows + 2;
#else
    const int row_step = out_cols + 2, col_step = 1;
#endif
    __global float* out = filtered + (size_t)view * (rows + 2) * (out_cols + 2) + (r0 + 1) * row_step + col_step;
    for (int k = lid; k < out_cols; k += lsize) {
        out[k * col_step] = buf[k].x;
        if (r1 < rows) out[k * col_step + row_step] = buf[k].y;
    }
}
