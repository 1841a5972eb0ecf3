/* Host build of the firmware: the same loop, with stdio for the input stream and output. */
#include "firmware.h"

int main(int argc, char **argv) { return firmware_run(argc > 1 ? argv[1] : 0); }
