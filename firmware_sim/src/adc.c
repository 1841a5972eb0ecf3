#include "adc.h"

#include "pt100.h"

float adc_counts_to_ohm(uint32_t counts) {
  /* counts < 2^24 convert exactly; one rounding in the multiply. */
  return (float)counts * (ADC_R_REF_OHM / (float)ADC_FULL_SCALE_COUNTS);
}

channel_state adc_read_channel(uint32_t counts, float *temperature_c) {
  if (counts >= ADC_FULL_SCALE_COUNTS - 1u) return CHANNEL_OPEN; /* railed */
  const float ohm = adc_counts_to_ohm(counts);
  if (ohm > ADC_OPEN_OHM) return CHANNEL_OPEN;
  if (ohm < ADC_SHORT_OHM) return CHANNEL_SHORT;
  *temperature_c = pt100_temperature(ohm);
  return CHANNEL_OK;
}
