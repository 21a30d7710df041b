// PLACEHOLDER: being implemented this session.
#include "drivers/synthetic/synthetic_source.h"
