/* Pt-100 resistance <-> temperature by the Callendar-Van Dusen equation with the IEC 60751
 * coefficients, in float, for -200 C .. 850 C:
 *   R(T) = R0 (1 + A T + B T^2)                  T >= 0 C
 *   R(T) = R0 (1 + A T + B T^2 + C (T-100) T^3)   T <  0 C            */
#ifndef FIRMWARE_PT100_H
#define FIRMWARE_PT100_H

#define PT100_R0 100.0f
#define PT100_A 3.9083e-3f
#define PT100_B (-5.775e-7f)
#define PT100_C (-4.183e-12f)

/* Temperature in C from resistance in ohm (R >= R0: closed form; R < R0: Newton on the full
 * quartic from the quadratic's root). Meaningful for 18.5 .. 390.5 ohm. */
float pt100_temperature(float resistance_ohm);
/* The forward equation (for tests and the ADC model). */
float pt100_resistance(float temperature_c);

#endif
