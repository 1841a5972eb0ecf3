/* The Pt-100 measurement channel: a 24-bit ratiometric ADC against a 400 ohm reference
 * resistor (the usual RTD front-end, e.g. ADS124S08 / ADS1220 class):
 *   counts = round(R / R_REF * 2^24), clipped to [0, 2^24 - 1].
 * An open sensor (broken wire) lets the input float to the reference voltage, which reads at
 * or near full scale; a shorted sensor reads near zero. 2^24 counts are exact in float, so the
 * conversion to ohm is a single rounding. */
#ifndef FIRMWARE_ADC_H
#define FIRMWARE_ADC_H

#include <stdint.h>

#define ADC_BITS 24
#define ADC_FULL_SCALE_COUNTS (1ul << ADC_BITS)
#define ADC_R_REF_OHM 400.0f
/* Healthy Pt-100 range with margin: 850 C is 390.48 ohm, -200 C is 18.52 ohm. Outside it the
 * channel is faulted; anything above OPEN_OHM is an open (or out-of-range hot) sensor. */
#define ADC_OPEN_OHM 395.0f
#define ADC_SHORT_OHM 15.0f

typedef enum channel_state {
  CHANNEL_OK = 0,
  CHANNEL_OPEN = 1,
  CHANNEL_SHORT = 2
} channel_state;

float adc_counts_to_ohm(uint32_t counts);
/* Classifies one reading; on CHANNEL_OK writes the temperature in C. */
channel_state adc_read_channel(uint32_t counts, float *temperature_c);

#endif
