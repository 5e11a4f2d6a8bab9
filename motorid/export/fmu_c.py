"""The FMI 2.0 C wrapper around the generated model function (one source file).

The motor has no state of its own: its outputs are an algebraic function of
its inputs (the rotor's inertia is left to the load model).  The wrapper
implements both FMI 2.0 interfaces in one binary:

- Model Exchange with zero continuous states and zero event indicators: the
  importer's solver integrates the load and asks for the torque at every
  stage with the current ω and θ, so no hold or delay enters the loop (the
  interface to prefer, and the reason it is there);
- Co-Simulation, for importers that take only that: ``fmi2DoStep`` advances
  time, and the outputs follow the inputs set at each communication point.

Outputs are evaluated lazily, when an output is read after an input changed.
"""

from __future__ import annotations

WRAPPER = r"""
/* ---- FMI 2.0 wrapper (motorid.export.fmu_c) ---- */
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

#define N_INPUTS @N_INPUTS@
#define N_OUTPUTS @N_OUTPUTS@
#define GUID "@GUID@"

typedef struct {
    double u[N_INPUTS];
    double y[N_OUTPUTS];
    int dirty;
    double time;
    fmi2Type type;
    fmi2CallbackFunctions cb;
    fmi2String name;
} Instance;

static const double start_values[N_INPUTS] = {@STARTS@};

static void update(Instance *m)
{
    if (m->dirty) {
        model_evaluate(m->u, m->y);
        m->dirty = 0;
    }
}

static void logError(Instance *m, const char *message)
{
    if (m && m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, fmi2Error, "logStatusError", message);
}

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[])
{
    (void)c; (void)loggingOn; (void)n; (void)categories;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation; (void)visible; (void)loggingOn;
    if (!functions) return NULL;
    if (!fmuGUID || strcmp(fmuGUID, GUID) != 0) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                              "wrong GUID: this binary belongs to another modelDescription.xml");
        return NULL;
    }
    Instance *m = (Instance*)calloc(1, sizeof(Instance));
    if (!m) return NULL;
    m->cb = *functions;
    m->type = fmuType;
    m->name = instanceName;
    memcpy(m->u, start_values, sizeof(start_values));
    m->dirty = 1;
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    ((Instance*)c)->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }

fmi2Status fmi2Reset(fmi2Component c)
{
    Instance *m = (Instance*)c;
    memcpy(m->u, start_values, sizeof(start_values));
    m->dirty = 1;
    m->time = 0.0;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    Instance *m = (Instance*)c;
    size_t i;
    for (i = 0; i < nvr; ++i) {
        if (vr[i] < N_INPUTS) {
            value[i] = m->u[vr[i]];
        } else if (vr[i] < N_INPUTS + N_OUTPUTS) {
            update(m);
            value[i] = m->y[vr[i] - N_INPUTS];
        } else {
            logError(m, "fmi2GetReal: unknown value reference");
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    Instance *m = (Instance*)c;
    size_t i;
    for (i = 0; i < nvr; ++i) {
        if (vr[i] >= N_INPUTS) {
            logError(m, "fmi2SetReal: only the inputs can be set");
            return fmi2Error;
        }
        m->u[vr[i]] = value[i];
        m->dirty = 1;
    }
    return fmi2OK;
}

static fmi2Status none(fmi2Component c, size_t nvr)
{
    if (nvr == 0) return fmi2OK;
    logError((Instance*)c, "this FMU has no variables of this type");
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{ (void)vr; (void)value; return none(c, nvr); }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{ (void)vr; (void)value; return none(c, nvr); }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{ (void)vr; (void)value; return none(c, nvr); }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{ (void)vr; (void)value; return none(c, nvr); }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{ (void)vr; (void)value; return none(c, nvr); }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{ (void)vr; (void)value; return none(c, nvr); }

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* s) { (void)s; logError((Instance*)c, "no FMU state"); return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)s; logError((Instance*)c, "no FMU state"); return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* s) { (void)s; logError((Instance*)c, "no FMU state"); return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { (void)s; (void)n; logError((Instance*)c, "no FMU state"); return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { (void)s; (void)b; (void)n; logError((Instance*)c, "no FMU state"); return fmi2Error; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate* s) { (void)s; (void)b; (void)n; logError((Instance*)c, "no FMU state"); return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[], size_t nUnknown,
                                        const fmi2ValueReference vKnown[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown; (void)nUnknown; (void)vKnown; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    logError((Instance*)c, "directional derivatives are not provided");
    return fmi2Error;
}

/* ---- Model Exchange: no continuous states, no event indicators ---- */
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo* info)
{
    (void)c;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean* enterEventMode, fmi2Boolean* terminateSimulation)
{
    (void)c; (void)noSetFMUStatePriorToCurrentPoint;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) { ((Instance*)c)->time = time; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) { (void)x; return none(c, nx); }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) { (void)derivatives; return none(c, nx); }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) { (void)eventIndicators; return none(c, ni); }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) { (void)x; return none(c, nx); }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) { (void)x_nominal; return none(c, nx); }

/* ---- Co-Simulation: a step only advances time ---- */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{ (void)vr; (void)order; (void)value; return none(c, nvr); }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{ (void)vr; (void)order; (void)value; return none(c, nvr); }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    (void)noSetFMUStatePriorToCurrentPoint;
    ((Instance*)c)->time = currentCommunicationPoint + communicationStepSize;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* value) { (void)c; (void)s; *value = fmi2OK; return fmi2OK; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value)
{ (void)s; *value = ((Instance*)c)->time; return fmi2OK; }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* value) { (void)c; (void)s; (void)value; return fmi2Discard; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value) { (void)c; (void)s; (void)value; return fmi2Discard; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* value) { (void)c; (void)s; (void)value; return fmi2Discard; }
"""


def wrapper_source(guid: str, starts, n_outputs: int) -> str:
    """The FMI 2.0 wrapper for a model function ``model_evaluate(u, y)`` defined above it."""
    from motorid.export.jaxpr_c import c_literal

    return (WRAPPER.replace("@N_INPUTS@", str(len(starts))).replace("@N_OUTPUTS@", str(n_outputs))
            .replace("@GUID@", guid).replace("@STARTS@", ", ".join(c_literal(s) for s in starts)))
