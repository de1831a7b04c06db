/* FMI 3.0 functions the test models do not implement: they fail (fmi3Error). Compiled
   without the FMI headers so that one prototype serves them all; with -DSCHEDULED_EXECUTION
   for the Scheduled Execution model (fmi3_scheduled.c), else for the co-simulation ones. */
int fmi3CompletedIntegratorStep(void) { return 3; }
int fmi3DeserializeFMUState(void) { return 3; }
int fmi3EnterConfigurationMode(void) { return 3; }
int fmi3EnterContinuousTimeMode(void) { return 3; }
int fmi3EvaluateDiscreteStates(void) { return 3; }
int fmi3ExitConfigurationMode(void) { return 3; }
int fmi3FreeFMUState(void) { return 3; }
int fmi3GetAdjointDerivative(void) { return 3; }
int fmi3GetContinuousStateDerivatives(void) { return 3; }
int fmi3GetContinuousStates(void) { return 3; }
int fmi3GetDirectionalDerivative(void) { return 3; }
int fmi3GetEventIndicators(void) { return 3; }
int fmi3GetFMUState(void) { return 3; }
int fmi3GetNominalsOfContinuousStates(void) { return 3; }
int fmi3GetNumberOfContinuousStates(void) { return 3; }
int fmi3GetNumberOfEventIndicators(void) { return 3; }
int fmi3GetNumberOfVariableDependencies(void) { return 3; }
int fmi3GetOutputDerivatives(void) { return 3; }
int fmi3GetVariableDependencies(void) { return 3; }
int fmi3InstantiateModelExchange(void) { return 3; }
int fmi3SerializeFMUState(void) { return 3; }
int fmi3SerializedFMUStateSize(void) { return 3; }
int fmi3SetContinuousStates(void) { return 3; }
int fmi3SetFMUState(void) { return 3; }
int fmi3SetIntervalDecimal(void) { return 3; }
int fmi3SetIntervalFraction(void) { return 3; }
int fmi3SetShiftDecimal(void) { return 3; }
int fmi3SetShiftFraction(void) { return 3; }
int fmi3SetTime(void) { return 3; }
#if defined(SCHEDULED_EXECUTION)
int fmi3DoStep(void) { return 3; }
int fmi3EnterEventMode(void) { return 3; }
int fmi3EnterStepMode(void) { return 3; }
int fmi3GetBinary(void) { return 3; }
int fmi3GetBoolean(void) { return 3; }
int fmi3GetFloat32(void) { return 3; }
int fmi3GetInt16(void) { return 3; }
int fmi3GetInt64(void) { return 3; }
int fmi3GetInt8(void) { return 3; }
int fmi3GetIntervalFraction(void) { return 3; }
int fmi3GetShiftFraction(void) { return 3; }
int fmi3GetString(void) { return 3; }
int fmi3GetUInt16(void) { return 3; }
int fmi3GetUInt32(void) { return 3; }
int fmi3GetUInt64(void) { return 3; }
int fmi3GetUInt8(void) { return 3; }
int fmi3InstantiateCoSimulation(void) { return 3; }
int fmi3SetBinary(void) { return 3; }
int fmi3SetBoolean(void) { return 3; }
int fmi3SetClock(void) { return 3; }
int fmi3SetFloat32(void) { return 3; }
int fmi3SetInt16(void) { return 3; }
int fmi3SetInt64(void) { return 3; }
int fmi3SetInt8(void) { return 3; }
int fmi3SetString(void) { return 3; }
int fmi3SetUInt16(void) { return 3; }
int fmi3SetUInt32(void) { return 3; }
int fmi3SetUInt64(void) { return 3; }
int fmi3SetUInt8(void) { return 3; }
int fmi3UpdateDiscreteStates(void) { return 3; }
#else
int fmi3ActivateModelPartition(void) { return 3; }
int fmi3InstantiateScheduledExecution(void) { return 3; }
#endif
