"""modelDescription.xml (FMI 2.0 and 3.0) and sources/buildDescription.xml (FMI 3.0).

Deterministic: the same model and options give the same bytes (no date; the GUID /
instantiation token is a hash of the FMU's content, filled in by the builder)."""
from __future__ import annotations

from .variables import Variable, unit_definition

TOKEN = "@MECHDSL_TOKEN@"          # replaced by the content hash


def _num(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    return repr(float(v))


def quoteattr(value: str) -> str:
    """An XML attribute value in double quotes (xml.sax.saxutils.quoteattr's escapes for that
    case; that module imports urllib, a tenth of a second of an export)."""
    value = value.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")
    return '"' + value.replace("\n", "&#10;").replace("\r", "&#13;").replace("\t", "&#9;") + '"'


def _attrs(**kw) -> str:
    return "".join(f" {k}={quoteattr(_num(v) if not isinstance(v, str) else v)}" for k, v in kw.items() if v is not None)


def _units(variables: list[Variable], fmi_version: int) -> list[str]:
    units = sorted({v.unit for v in variables if v.unit})
    if not units:
        return []
    lines = ["  <UnitDefinitions>"]
    for u in units:
        base, factor = unit_definition(u)
        if base:
            extra = {"factor": factor} if factor != 1.0 else {}
            lines.append(f"    <Unit{_attrs(name=u)}>")
            lines.append(f"      <BaseUnit{_attrs(**base, **extra)}/>")
            lines.append("    </Unit>")
        else:
            lines.append(f"    <Unit{_attrs(name=u)}/>")
    lines.append("  </UnitDefinitions>")
    return lines


def _experiment(exp: dict) -> str:
    return f"  <DefaultExperiment{_attrs(startTime=exp['start'], stopTime=exp['stop'], tolerance=exp['tolerance'], stepSize=exp['step'])}/>"


def _initial_unknowns(variables: list[Variable]) -> list[Variable]:
    by_vr = {v.vr: v for v in variables}
    chosen = {v.vr for v in variables if v.causality == "output" and v.initial in ("approx", "calculated")}
    chosen |= {v.vr for v in variables if v.causality == "calculatedParameter"}
    for d in variables:
        if d.derivative_of is not None:
            for v in (d, by_vr[d.derivative_of]):
                if v.initial in ("approx", "calculated"):
                    chosen.add(v.vr)
    return [v for v in variables if v.vr in chosen]


def _derivatives(variables: list[Variable]) -> list[Variable]:
    """The state derivatives in the order of the continuous states (x = [q; der(q)])."""
    states = [v for v in variables if v.kind == "state"]
    of = {v.derivative_of: v for v in variables if v.derivative_of is not None}
    return [of[s.vr] for s in states]


def model_description_2(meta: dict, variables: list[Variable]) -> str:
    ident = meta["identifier"]
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<fmiModelDescription fmiVersion="2.0"{_attrs(modelName=meta["model"], guid=TOKEN, description=meta["description"] or None, generationTool=meta["tool"])}'
             f' variableNamingConvention="flat" numberOfEventIndicators="{meta.get("event_indicators", 0)}">']
    sources = "".join(f'\n      <File name="{f}"/>' for f in meta["sources"])
    if meta["me"]:
        lines.append(f'  <ModelExchange{_attrs(modelIdentifier=ident)} needsExecutionTool="false"'
                     f' completedIntegratorStepNotNeeded="{"false" if meta["constrained"] or meta["contacts"] else "true"}"'
                     ' canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="true"'
                     ' canGetAndSetFMUstate="true" canSerializeFMUstate="true"'
                     f' providesDirectionalDerivative="{"false" if meta["contacts"] else "true"}">'
                     f'\n    <SourceFiles>{sources}\n    </SourceFiles>\n  </ModelExchange>')
    if meta["cs"]:
        lines.append(f'  <CoSimulation{_attrs(modelIdentifier=ident)} needsExecutionTool="false"'
                     ' canHandleVariableCommunicationStepSize="true" canInterpolateInputs="true"'
                     ' maxOutputDerivativeOrder="0" canRunAsynchronuously="false"'
                     ' canBeInstantiatedOnlyOncePerProcess="false" canNotUseMemoryManagementFunctions="true"'
                     ' canGetAndSetFMUstate="true" canSerializeFMUstate="true"'
                     f' providesDirectionalDerivative="{"false" if meta["contacts"] else "true"}">'
                     f'\n    <SourceFiles>{sources}\n    </SourceFiles>\n  </CoSimulation>')
    lines += _units(variables, 2)
    lines += ["  <LogCategories>", '    <Category name="logStatusError" description="errors"/>',
              '    <Category name="logAll" description="every message"/>', "  </LogCategories>"]
    lines.append(_experiment(meta["experiment"]))
    lines.append("  <ModelVariables>")
    index = {v.vr: i + 1 for i, v in enumerate(variables)}
    for i, v in enumerate(variables):
        lines.append(f"    <!-- index {i + 1} -->")
        lines.append(f"    <ScalarVariable{_attrs(name=v.name, valueReference=v.vr, description=v.description or None, causality=v.causality, variability=v.variability, initial=v.initial if v.causality != 'input' else None)}>")
        if v.type == "Real":
            lines.append(f"      <Real{_attrs(unit=v.unit, start=v.start, min=v.min, max=v.max, derivative=index[v.derivative_of] if v.derivative_of is not None else None)}/>")
        else:
            lines.append(f"      <Integer{_attrs(start=v.start, min=v.min, max=v.max)}/>")
        lines.append("    </ScalarVariable>")
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    outs = [v for v in variables if v.causality == "output"]
    if outs:
        lines += ["    <Outputs>"] + [f'      <Unknown index="{index[v.vr]}"/>' for v in outs] + ["    </Outputs>"]
    ders = _derivatives(variables)
    if ders:
        lines += ["    <Derivatives>"] + [f'      <Unknown index="{index[v.vr]}"/>' for v in ders] + ["    </Derivatives>"]
    init = _initial_unknowns(variables)
    if init:
        lines += ["    <InitialUnknowns>"] + [f'      <Unknown index="{index[v.vr]}"/>' for v in init] + ["    </InitialUnknowns>"]
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


def model_description_3(meta: dict, variables: list[Variable]) -> str:
    ident = meta["identifier"]
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<fmiModelDescription fmiVersion="3.0"{_attrs(modelName=meta["model"], instantiationToken=TOKEN, description=meta["description"] or None, generationTool=meta["tool"])}'
             ' variableNamingConvention="flat">']
    if meta["me"]:
        lines.append(f'  <ModelExchange{_attrs(modelIdentifier=ident)} needsExecutionTool="false"'
                     f' needsCompletedIntegratorStep="{"true" if meta["constrained"] or meta["contacts"] else "false"}"'
                     ' canBeInstantiatedOnlyOncePerProcess="false" canGetAndSetFMUState="true"'
                     ' canSerializeFMUState="true"'
                     f' providesDirectionalDerivatives="{"false" if meta["contacts"] else "true"}"/>')
    if meta["cs"]:
        lines.append(f'  <CoSimulation{_attrs(modelIdentifier=ident)} needsExecutionTool="false"'
                     ' canBeInstantiatedOnlyOncePerProcess="false" canGetAndSetFMUState="true"'
                     ' canSerializeFMUState="true"'
                     f' providesDirectionalDerivatives="{"false" if meta["contacts"] else "true"}"'
                     ' canHandleVariableCommunicationStepSize="true" maxOutputDerivativeOrder="0"'
                     ' providesIntermediateUpdate="false" canReturnEarlyAfterIntermediateUpdate="false"'
                     ' hasEventMode="false"/>')
    lines += _units(variables, 3)
    lines += ["  <LogCategories>", '    <Category name="logStatusError" description="errors"/>',
              '    <Category name="logAll" description="every message"/>', "  </LogCategories>"]
    lines.append(_experiment(meta["experiment"]))
    lines.append("  <ModelVariables>")
    for v in variables:
        tag = "Float64" if v.type == "Real" else "Int32"
        initial = v.initial if v.causality not in ("input", "independent") else None
        lines.append(f"    <{tag}{_attrs(name=v.name, valueReference=v.vr, description=v.description or None, causality=v.causality, variability=v.variability, initial=initial, unit=v.unit if tag == 'Float64' else None, start=v.start, min=v.min, max=v.max, derivative=v.derivative_of)}/>")
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    lines += [f'    <Output valueReference="{v.vr}"/>' for v in variables if v.causality == "output"]
    lines += [f'    <ContinuousStateDerivative valueReference="{v.vr}"/>' for v in _derivatives(variables)]
    lines += [f'    <InitialUnknown valueReference="{v.vr}"/>' for v in _initial_unknowns(variables)]
    lines += [f'    <EventIndicator valueReference="{v.vr}"/>' for v in variables if v.kind == "event_indicator"]
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


def build_description(identifier: str, sources: list[str]) -> str:
    """sources/buildDescription.xml of an FMI 3.0 FMU (how to compile the sources)."""
    files = "".join(f'\n        <SourceFile name="{f}"/>' for f in sources)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration{_attrs(modelIdentifier=identifier)}>\n'
            f'    <SourceFileSet language="C11">{files}\n    </SourceFileSet>\n'
            '    <Library name="m"/>\n'
            '  </BuildConfiguration>\n'
            '</fmiBuildDescription>\n')
