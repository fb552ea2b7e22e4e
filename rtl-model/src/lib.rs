//! Bit-accurate register-transfer model of the occlusion engine and OccU Control (no floats).
