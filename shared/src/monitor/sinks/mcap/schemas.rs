//! The JSON Schemas of run.mcap's channels, made from the scenario's vectors, so that a viewer
//! plots each field by its name and unit.

use serde_json::{Value, json};

use super::{Detail, HEADER_ROLES};
use crate::config::schema::Component;
use crate::contract::report::{FaultEffect, HOPS};
use crate::contract::run_format::field;
use crate::model::layout::VectorLayout;

/// The JSON Schemas of the channels, in [`Channel::ALL`]'s order. Every float may be null: a
/// non-finite value (a corrupted command's NaN), which JSON cannot hold.
pub(super) fn schemas(layout: &VectorLayout, detail: Detail) -> Vec<Value> {
    let float = || json!({"type": ["number", "null"]});
    // A component's field keeps its name (a viewer plots by name) and gives its unit here.
    let component = |c: &Component| {
        let mut field = float();
        if !matches!(c.unit, "1" | "") {
            field["description"] = c.unit.into();
        }
        (c.name.to_string(), field)
    };
    let integer = |description: &str| json!({"type": "integer", "description": description});
    let boolean = |description: &str| json!({"type": "boolean", "description": description});
    let object = |title: &str, properties: Vec<(String, Value)>| {
        let required: Vec<&String> = properties.iter().map(|(name, _)| name).collect();
        json!({
            "title": title,
            "type": "object",
            "required": required,
            "properties": properties.iter().cloned().collect::<serde_json::Map<_, _>>(),
        })
    };
    let loop_fields = || {
        vec![
            (field::K.to_string(), integer("loop index: the plant tick the data derives from")),
            (field::T.to_string(), json!({"type": "number", "description": "simulation time of tick k, s"})),
        ]
    };
    let vector = |title: &str, components: &[Component]| {
        let mut properties = loop_fields();
        properties.extend(components.iter().map(component));
        object(title, properties)
    };
    let live = detail == Detail::Live;
    let applied = || {
        let description = "the input the actuator applied over the last interval";
        let mut applied = object("looplab.Applied", layout.input.iter().map(component).collect());
        applied["description"] = description.into();
        (field::APPLIED.to_string(), applied)
    };
    // Only on a message whose header says an upstream stage dropped the loop's output.
    let lost = boolean("an upstream stage dropped this loop's output (lockstep drop fault); absent: not lost");
    // Only after the sending process's first restart.
    let incarnation = integer("the incarnation of the process that sent it; absent: 0");
    let with_lost = |mut schema: Value| {
        if live {
            schema["properties"][field::LOST] = lost.clone();
            schema["properties"][field::INCARNATION] = incarnation.clone();
        }
        schema
    };

    let mut measurements = loop_fields();
    for (name, components) in &layout.sensors {
        let mut sensor = vec![(
            field::VALUE.to_string(),
            object(&format!("{name} value"), components.iter().map(component).collect()),
        )];
        if live {
            sensor.extend([
                (field::SAMPLE_TIME.into(), json!({"type": "number", "description": "when the truth behind the value was sampled (simulation time), s"})),
                (field::SEQ.into(), integer("samples this sensor delivered before this one")),
                (field::FRESH.into(), boolean("delivered at this tick (else held)")),
                (field::VALID.into(), boolean("the sensor's first sample has arrived")),
            ]);
        }
        measurements.push((name.clone(), object(&format!("looplab.Reading.{name}"), sensor)));
    }
    if live {
        measurements.push(applied());
    }
    let mut state = loop_fields();
    state.extend(layout.state.iter().map(component));
    if live {
        state.push(applied());
    }

    let ns = |description: &str| json!({"type": "integer", "description": format!("{description}, ns")});
    let mut record = loop_fields();
    record.push((field::DEADLINE_MISS.into(), boolean("the command reached the plant after tick k+1 was due")));
    record.push((field::REJECTED.into(), boolean("the plant rejected the command (non-finite or out of range)")));
    if live {
        record.push((field::LOST.into(), boolean("the command arrived marked lost (lockstep drop fault)")));
        let incarnations = HEADER_ROLES.iter().map(|r| (r.name().to_string(), integer("0 before the first restart")));
        record.push((field::INCARNATIONS.into(), object("looplab.Incarnations", incarnations.collect())));
    }

    let mut latency = loop_fields();
    latency.push(("end_to_end_ns".into(), ns("plant publish of loop k to command k reaching the plant")));
    latency.extend(HOPS.iter().map(|(name, _, _)| (format!("{name}_ns"), ns(name))));
    let mut latency = object("looplab.Latency", latency);
    // Real time only.
    latency["properties"]["wake_latency_ns"] = ns("plant wake-up minus the tick's scheduled time");
    latency["properties"]["tick_period_error_ns"] = ns("time since the previous wake-up minus the period");

    let mut faults = vec![
        ("k".to_string(), integer("the tick of the injection")),
        ("t".to_string(), json!({"type": "number", "description": "simulation time of the injection, s"})),
        ("index".to_string(), integer("the fault's place in the launch file's [[faults]]")),
        ("fault".to_string(), json!({"type": "string", "description": "in the --fault form"})),
        ("kind".to_string(), json!({"type": "string"})),
        ("process".to_string(), json!({"type": "string"})),
        ("duration_s".to_string(), float()),
    ];
    let mut faults_schema = object("looplab.Fault", std::mem::take(&mut faults));
    // What the fault did (absent when the monitor has no record of it): FaultEffect's fields.
    let effect = serde_json::to_value(FaultEffect::default()).expect("a struct is JSON");
    for (name, value) in effect.as_object().expect("a struct is an object") {
        faults_schema["properties"][name] = match value {
            Value::Bool(_) => json!({"type": "boolean"}),
            Value::Number(_) => json!({"type": "integer"}),
            _ => float(),
        };
    }

    vec![
        with_lost(object("looplab.State", state)),
        with_lost(object("looplab.Measurements", measurements)),
        with_lost(vector("looplab.Estimate", &layout.estimate)),
        with_lost(vector("looplab.Command", &layout.input)),
        object("looplab.Loop", record),
        latency,
        faults_schema,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn layout() -> VectorLayout {
        VectorLayout::example()
    }

    #[test]
    fn schemas_name_every_component_of_the_layout() {
        let schemas = schemas(&layout(), Detail::Live);
        let titles: Vec<&str> = schemas.iter().map(|s| s["title"].as_str().unwrap()).collect();
        assert_eq!(
            titles,
            [
                "looplab.State",
                "looplab.Measurements",
                "looplab.Estimate",
                "looplab.Command",
                "looplab.Loop",
                "looplab.Latency",
                "looplab.Fault"
            ]
        );
        let float = json!({"type": ["number", "null"]});
        assert_eq!(schemas[0]["required"], json!(["k", "t", "theta", "omega", "applied"]));
        assert_eq!(schemas[0]["properties"]["applied"]["required"], json!(["u"]));
        assert_eq!(schemas[0]["properties"]["applied"]["properties"]["u"]["description"], "N·m");
        assert_eq!(schemas[0]["properties"]["omega"], json!({"type": ["number", "null"], "description": "rad/s"}));
        assert_eq!(schemas[0]["properties"]["k"]["type"], "integer");
        let imu = &schemas[1]["properties"]["imu"];
        assert_eq!(imu["required"], json!(["value", "sample_time", "seq", "fresh", "valid"]));
        assert_eq!(imu["properties"]["seq"]["type"], "integer");
        assert_eq!(imu["properties"]["valid"]["type"], "boolean");
        assert_eq!(imu["properties"]["value"]["required"], json!(["x", "y"]));
        assert_eq!(imu["properties"]["value"]["properties"]["x"]["description"], "m/s²");
        // A pure number has no unit to give.
        assert_eq!(imu["properties"]["value"]["properties"]["y"], float);
        assert_eq!(imu["properties"]["fresh"]["type"], "boolean");
        assert_eq!(schemas[1]["required"], json!(["k", "t", "encoder", "imu", "applied"]));
        assert_eq!(schemas[3]["required"], json!(["k", "t", "u"]));
        // `lost` is written only on a lost message.
        for schema in &schemas[..4] {
            assert_eq!(schema["properties"]["lost"]["type"], "boolean", "{}", schema["title"]);
            assert!(!schema["required"].as_array().unwrap().contains(&json!("lost")), "{}", schema["title"]);
        }
        let latency = &schemas[5];
        assert_eq!(latency["required"].as_array().unwrap().len(), 2 + 1 + HOPS.len());
        assert_eq!(latency["properties"]["plant_to_sensors_ns"]["type"], "integer");
        assert_eq!(schemas[6]["properties"]["within_limits"]["type"], "boolean");
        assert_eq!(schemas[6]["properties"]["recovery_s"], float);

        // A run folder's files keep no sample times, flags or incarnations, and export keeps the
        // applied input nowhere.
        let files = super::schemas(&layout(), Detail::Files);
        assert_eq!(files[0]["required"], json!(["k", "t", "theta", "omega"]));
        assert_eq!(files[1]["required"], json!(["k", "t", "encoder", "imu"]));
        assert_eq!(files[1]["properties"]["imu"]["required"], json!(["value"]));
        assert!(files[..4].iter().all(|schema| schema["properties"].get("lost").is_none()));
        assert_eq!(files[4]["required"], json!(["k", "t", "deadline_miss", "rejected"]));
    }

    #[test]
    fn no_built_in_vector_or_sensor_has_the_name_of_a_message_field() {
        // They would collide with the loop's `k`, `t` and `lost` in every message, and with
        // `applied` in /state and /measurements (whose sensors are fields too).
        for entry in crate::scenarios::ALL {
            let (config, scenario) = crate::scenarios::resolve(entry.name, &[]).unwrap();
            let layout = VectorLayout::new(&config, scenario.as_ref());
            let components = layout.state.iter().chain(&layout.estimate).chain(&layout.input).map(|c| c.name);
            for name in components.chain(layout.sensors.iter().map(|(name, _)| name.as_str())) {
                assert!(!["k", "t", "lost", "applied"].contains(&name), "{}: a field is named {name}", entry.name);
            }
        }
    }
}
