// Lengths in fixed point: a distance t (mm) as whole units of 1 / u_fixed_scale mm, modulo 2^32.
// Integer sums are exact and order-independent, so a length summed from crossings in any order
// has the error of its crossings' t alone; they wrap modulo 2^32, so only the final length
// (< 2^31 units: u_fixed_scale is set from the scene size) must fit, never a single term.
uniform float u_fixed_scale;  // fixed-point units per mm, a power of two

// t in units, modulo 2^32 (negative t as its two's complement).
uint fixed_units(float t) {
    float a = round(abs(t) * u_fixed_scale);
    // a mod 2^32, exact in float32: above 2^32 the spacing of floats is already >= 2^9.
    uint magnitude = uint(a - 4294967296.0 * floor(a * (1.0 / 4294967296.0)));
    return t >= 0.0 ? magnitude : 0u - magnitude;
}
