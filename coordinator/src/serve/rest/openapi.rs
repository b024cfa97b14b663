//! The OpenAPI 3.1 document of the REST API, served at `/api/v1/openapi.json`. Paths and
//! schemas come from the handlers' `#[utoipa::path]` attributes as they are registered
//! ([`super::router`]); this module adds what is the same for every route: the bearer token,
//! the problem document of every error, and binary bodies described as such.

use super::dto::Problem;
use axum::http::header;
use axum::response::IntoResponse;
use serde_json::{Value, json};
use utoipa::OpenApi;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "Tessera",
        description = "Render jobs of Mitsuba 3 scenes on a farm: submit, watch, control, download.",
        license(name = "MIT OR Apache-2.0", identifier = "MIT OR Apache-2.0")
    ),
    components(schemas(Problem)),
    tags(
        (name = "jobs", description = "submit, list, control and delete jobs"),
        (name = "outputs", description = "a job's images and reports"),
        (name = "events", description = "server-sent events"),
        (name = "farm", description = "workers, disk, metrics, health")
    )
)]
struct Base;

/// The document's fixed part, before the routes add their paths.
pub fn base() -> utoipa::openapi::OpenApi {
    Base::openapi()
}

/// Media types whose bodies are bytes, not JSON: their schemas are dropped (OpenAPI 3.1 leaves
/// a binary body's schema out).
fn is_binary(media_type: &str) -> bool {
    media_type.starts_with("image/") || media_type == "application/x-tar"
}

/// Paths open without a token.
const PUBLIC: [&str; 2] = ["/api/v1/healthz", "/api/v1/openapi.json"];

/// The finished document as JSON text.
pub fn document(api: utoipa::openapi::OpenApi) -> String {
    let mut doc = serde_json::to_value(api).expect("invariant: the OpenAPI document serialises");
    doc["components"]["securitySchemes"] = json!({"bearer": {"type": "http", "scheme": "bearer"}});
    doc["security"] = json!([{"bearer": []}]);
    let problem = json!({"$ref": "#/components/schemas/Problem"});
    let error =
        |what: &str| json!({"description": what, "content": {"application/problem+json": {"schema": problem.clone()}}});
    let openapi_path = json!({"get": {
        "tags": ["farm"], "operationId": "openapi", "summary": "This document.",
        "responses": {"200": {"description": "the OpenAPI 3.1 document", "content": {"application/json": {}}}}
    }});
    doc["paths"]["/api/v1/openapi.json"] = openapi_path;
    let paths = doc["paths"].as_object_mut().expect("invariant: the document has paths");
    for (path, item) in paths.iter_mut() {
        for operation in item.as_object_mut().into_iter().flat_map(|o| o.values_mut()) {
            if PUBLIC.contains(&path.as_str()) {
                operation["security"] = json!([]);
                continue;
            }
            let responses = &mut operation["responses"];
            responses["4XX"] =
                error("the request is wrong: a bad field, an unknown job, a state that does not allow it");
            responses["5XX"] = error("the coordinator failed (its log says why) or its disk is full");
            for response in responses.as_object_mut().into_iter().flat_map(|r| r.values_mut()) {
                // `get_mut`: indexing would add a null `content` to responses without a body
                let contents = response.get_mut("content").and_then(Value::as_object_mut);
                for (media, content) in contents.into_iter().flat_map(|c| c.iter_mut()) {
                    if is_binary(media) {
                        content.as_object_mut().map(|c| c.remove("schema"));
                    }
                }
            }
        }
    }
    serde_json::to_string_pretty(&doc).expect("invariant: JSON values serialise")
}

/// `GET /api/v1/openapi.json`: the document made at start-up, shared without copying.
pub async fn serve(doc: axum::body::Bytes) -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "application/json")], doc)
}

/// `GET /api/v1/healthz` (and `/healthz`): `ok` while the coordinator serves.
#[utoipa::path(get, path = "/api/v1/healthz", tag = "farm",
    responses((status = 200, description = "`ok`", content_type = "text/plain", body = String)))]
pub async fn healthz() -> &'static str {
    "ok"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_operation_documents_its_errors_and_token() {
        let api = utoipa_axum::router::OpenApiRouter::<()>::with_openapi(base())
            .routes(utoipa_axum::routes!(healthz))
            .split_for_parts()
            .1;
        let doc: Value = serde_json::from_str(&document(api)).unwrap();
        assert_eq!(doc["openapi"], "3.1.0");
        assert_eq!(doc["paths"]["/api/v1/healthz"]["get"]["security"], json!([]));
        assert!(doc["paths"]["/api/v1/openapi.json"]["get"].is_object());
        assert!(doc["components"]["schemas"]["Problem"]["properties"]["detail"].is_object());
        let ok = &doc["paths"]["/api/v1/healthz"]["get"]["responses"]["200"];
        assert!(ok["content"]["text/plain"].is_object(), "{ok}");
    }
}
