//! Values pinned from PyTorch (torch 1.13, float64): `tools/pytorch/pinned_values.py` printed the
//! constants in `values` below; rerun it and paste to regenerate. Inputs are `sin(0.7 k + seed)`
//! over the flat row-major index (built the same way here), the loss is `Σ out ⊙ R` with
//! `R = pinned(out.shape, 99)`, so the gradients are `dL/d(input)`.

use crate::gradcheck::ix2;
use crate::*;
use ndarray::{Array1, Array2, ArrayD, IxDyn};

/// `sin(0.7 k + seed)` over the flat row-major index k, as the script's `pinned`.
fn pinned(shape: &[usize], seed: u64) -> ArrayD<f64> {
    let n = shape.iter().product::<usize>();
    ArrayD::from_shape_vec(
        IxDyn(shape),
        (0..n)
            .map(|k| (0.7 * k as f64 + seed as f64).sin())
            .collect(),
    )
    .unwrap()
}

fn p1(n: usize, seed: u64) -> Array1<f64> {
    pinned(&[n], seed).into_dimensionality().unwrap()
}

fn p2(r: usize, c: usize, seed: u64) -> Array2<f64> {
    ix2(&pinned(&[r, c], seed))
}

/// dL/dout of the script's loss for an output of `shape`.
fn r(shape: (usize, usize)) -> Array2<f64> {
    p2(shape.0, shape.1, 99)
}

#[track_caller]
fn assert_close<'a>(what: &str, got: impl IntoIterator<Item = &'a f64>, want: &[f64]) {
    let got: Vec<f64> = got.into_iter().copied().collect();
    assert_eq!(got.len(), want.len(), "{what}: length");
    let worst = got
        .iter()
        .zip(want)
        .map(|(g, w)| (g - w).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-12,
        "{what}: largest difference from PyTorch {worst:e}\n got {got:?}\nwant {want:?}"
    );
}

#[test]
fn linear_matches_pytorch() {
    let mut lin = Linear::from_values(p2(4, 3, 2), Some(p1(4, 3))).unwrap();
    let x = p2(5, 3, 1);
    let mut out = Array2::zeros((5, 4));
    lin.forward(out.view_mut(), x.view()).unwrap();
    assert_close("linear out", &out, values::LINEAR_OUT);
    let mut dx = Array2::zeros((5, 3));
    lin.backward(dx.view_mut(), r((5, 4)).view(), x.view())
        .unwrap();
    assert_close("linear dx", &dx, values::LINEAR_DX);
    assert_close("linear dweight", &lin.weight.grad, values::LINEAR_DW);
    assert_close("linear dbias", &lin.bias.unwrap().grad, values::LINEAR_DB);
}

#[test]
fn batch_norm_matches_pytorch_in_training_then_evaluation() {
    let mut bn = BatchNorm::new(3);
    bn.weight.value = p1(3, 5);
    bn.bias.value = p1(3, 6);
    let x = p2(6, 3, 4);
    let (mut out, mut dx, mut cache) = (
        Array2::zeros((6, 3)),
        Array2::zeros((6, 3)),
        BatchNormCache::default(),
    );
    bn.forward(out.view_mut(), x.view(), true, &mut cache)
        .unwrap();
    assert_close("batch norm training out", &out, values::BN_TRAIN_OUT);
    bn.backward(dx.view_mut(), r((6, 3)).view(), x.view(), &cache)
        .unwrap();
    assert_close("batch norm training dx", &dx, values::BN_TRAIN_DX);
    assert_close("batch norm dweight", &bn.weight.grad, values::BN_DWEIGHT);
    assert_close("batch norm dbias", &bn.bias.grad, values::BN_DBIAS);
    assert_close(
        "batch norm running mean",
        &bn.running_mean,
        values::BN_RUNNING_MEAN,
    );
    assert_close(
        "batch norm running var",
        &bn.running_var,
        values::BN_RUNNING_VAR,
    );
    bn.forward(out.view_mut(), x.view(), false, &mut cache)
        .unwrap();
    assert_close("batch norm evaluation out", &out, values::BN_EVAL_OUT);
    dx.fill(0.0);
    bn.backward(dx.view_mut(), r((6, 3)).view(), x.view(), &cache)
        .unwrap();
    assert_close("batch norm evaluation dx", &dx, values::BN_EVAL_DX);
}

#[test]
fn layer_norm_matches_the_annotated_transformer() {
    let mut ln = LayerNorm::new(5);
    ln.scale.value = p1(5, 8);
    ln.shift.value = p1(5, 9);
    let x = p2(4, 5, 7);
    let (mut out, mut dx, mut cache) = (
        Array2::zeros((4, 5)),
        Array2::zeros((4, 5)),
        LayerNormCache::default(),
    );
    ln.forward(out.view_mut(), x.view(), &mut cache).unwrap();
    assert_close("layer norm out", &out, values::LN_OUT);
    ln.backward(dx.view_mut(), r((4, 5)).view(), x.view(), &cache)
        .unwrap();
    assert_close("layer norm dx", &dx, values::LN_DX);
    assert_close("layer norm da", &ln.scale.grad, values::LN_DA);
    assert_close("layer norm db", &ln.shift.grad, values::LN_DB);
}

#[test]
fn softmax_rows_matches_pytorch() {
    let x = p2(3, 5, 10) * 3.0;
    let (mut out, mut dx) = (Array2::zeros((3, 5)), Array2::zeros((3, 5)));
    softmax_rows_forward(out.view_mut(), x.view()).unwrap();
    assert_close("softmax out", &out, values::SOFTMAX_OUT);
    softmax_rows_backward(dx.view_mut(), r((3, 5)).view(), out.view()).unwrap();
    assert_close("softmax dx", &dx, values::SOFTMAX_DX);
}

#[test]
fn l1_normalize_columns_matches_pytorch_with_a_zero_column() {
    let mut x = p2(4, 3, 11);
    x.column_mut(1).fill(0.0);
    let (mut out, mut dx, mut cache) = (
        Array2::zeros((4, 3)),
        Array2::zeros((4, 3)),
        L1NormalizeCache::default(),
    );
    l1_normalize_columns_forward(out.view_mut(), x.view(), &mut cache).unwrap();
    assert_close("l1 normalise out", &out, values::L1_OUT);
    l1_normalize_columns_backward(
        dx.view_mut(),
        r((4, 3)).view(),
        x.view(),
        out.view(),
        &cache,
    )
    .unwrap();
    assert_close("l1 normalise dx", &dx, values::L1_DX);
}

#[test]
fn attention_matches_the_annotated_transformer() {
    let lin = |i: u64| Linear::from_values(p2(4, 4, 20 + i), Some(p1(4, 30 + i))).unwrap();
    let mut mha = MultiHeadAttention {
        heads: 2,
        query: lin(0),
        key: lin(1),
        value: lin(2),
        output: lin(3),
    };
    let (q, kv) = (p2(3, 4, 12), p2(5, 4, 13));
    let (mut out, mut cache) = (Array2::zeros((3, 4)), AttentionCache::default());
    mha.forward(out.view_mut(), q.view(), kv.view(), &mut cache)
        .unwrap();
    assert_close("attention out", &out, values::MHA_OUT);
    let (mut dq, mut dkv) = (Array2::zeros((3, 4)), Array2::zeros((5, 4)));
    mha.backward(
        dq.view_mut(),
        Some(dkv.view_mut()),
        r((3, 4)).view(),
        q.view(),
        kv.view(),
        &mut cache,
    )
    .unwrap();
    assert_close("attention dq", &dq, values::MHA_DQ);
    assert_close("attention dkv", &dkv, values::MHA_DKV);
    assert_close("attention dWq", &mha.query.weight.grad, values::MHA_DWQ);
    assert_close("attention dWk", &mha.key.weight.grad, values::MHA_DWK);
    assert_close("attention dWv", &mha.value.weight.grad, values::MHA_DWV);
    assert_close("attention dWo", &mha.output.weight.grad, values::MHA_DWO);
    assert_close(
        "attention dbq",
        &mha.query.bias.unwrap().grad,
        values::MHA_DBQ,
    );
    assert_close(
        "attention dbo",
        &mha.output.bias.unwrap().grad,
        values::MHA_DBO,
    );
}

#[test]
fn max_over_neighbours_matches_pytorch() {
    let x = p2(12, 2, 14);
    let (mut out, mut dx, mut cache) = (
        Array2::zeros((3, 2)),
        Array2::zeros((12, 2)),
        MaxKCache::default(),
    );
    max_k_forward(out.view_mut(), x.view(), 4, &mut cache).unwrap();
    assert_close("max_k out", &out, values::MAXK_OUT);
    max_k_backward(dx.view_mut(), r((3, 2)).view(), 4, &cache).unwrap();
    assert_close("max_k dx", &dx, values::MAXK_DX);
}

#[test]
fn optimisers_match_pytorch_over_three_steps() {
    // A one-tensor model whose gradient at step t is pinned((2, 3), 41 + t).
    struct One(Param<f64, ndarray::Ix2>);
    impl Parameters<f64> for One {
        fn visit_params(
            &mut self,
            prefix: &str,
            f: &mut dyn FnMut(&str, param::ParamViewMut<'_, f64>),
        ) {
            f(&param::join_name(prefix, "p"), self.0.view_mut());
        }
    }
    let run = |step: &mut dyn FnMut(&mut One)| {
        let mut model = One(Param::new(p2(2, 3, 40)));
        for t in 0..3 {
            model.0.grad = p2(2, 3, 41 + t);
            step(&mut model);
        }
        model.0.value
    };
    let mut sgd = optim::Sgd::new(0.1, 0.9, 0.01);
    assert_close(
        "sgd",
        &run(&mut |m| sgd.step(m).unwrap()),
        values::SGD_AFTER_3,
    );
    let mut adam = optim::Adam::new(0.01, 0.01);
    assert_close(
        "adam",
        &run(&mut |m| adam.step(m).unwrap()),
        values::ADAM_AFTER_3,
    );
}

/// Printed by `tools/pytorch/pinned_values.py`.
#[rustfmt::skip]
mod values {
    pub const LINEAR_OUT: &[f64] = &[1.1574763916808497, -2.6828204877191464, 0.20589306399315366, 0.05845584157623818, 0.16723256879749995, 0.735337448825821, -2.255150551467122, -0.8748055299377892, -0.9016020247001574, 0.3457122890621862, -0.792914469647928, -1.96158874999771, 1.167835760160921, -2.679044159161245, 0.19172076598879106, 0.06898917189979847, 0.14717514486083275, 0.7646540211001879, -2.2646938421563236, -0.8944863159531412];
    pub const LINEAR_DX: &[f64] = &[0.19274716004983, 0.4552270822289368, 0.5036065945164012, -0.12727980993919724, -0.33978327018646404, -0.3924813492049855, 0.04710460083170341, 0.1850756940813401, 0.23600279651703038, 0.03851379543538708, -0.008981637169924284, -0.05225286547226775, -0.1196817177980174, -0.1681502956867627, -0.13753516209317732];
    pub const LINEAR_DW: &[f64] = &[0.36996134937199754, -0.5777666443686138, -1.2537619574098169, 1.0949434733676735, 0.5326835189704485, -0.280105817808162, 1.3049565728748218, 1.3926042999281365, 0.8252884646828167, 0.9012282056500083, 1.597561518587179, 1.5425366867454848];
    pub const LINEAR_DB: &[f64] = &[-0.5334085419837735, -0.6656177351975257, -0.4847765069838589, -0.0759373126938302];
    pub const BN_TRAIN_OUT: &[f64] = &[0.7508007261878065, 1.1835675812933477, 0.7721540553183966, -0.03086203253791805, 0.0181576621058867, 1.0534287907464392, -1.55829434053905, 0.01276952424565264, 0.8705459795303789, 0.7656049196553576, 1.183619804252686, 0.7739265937837345, -0.05338575032678348, 0.006809536250513886, 1.0543652460458437, -1.550356511632968, 0.02417541555150273, 0.8678279094449687];
    pub const BN_TRAIN_DX: &[f64] = &[0.6061379134795063, 0.0021227024934403435, 0.07177683544944967, -0.9164404229614728, -0.463369504532916, 0.03863100629302302, 0.3102891720801897, 0.4612687888133499, -0.11041646711548164, 0.5942481936128805, -0.006839085279737607, 0.07322143474241347, -0.9191926132023279, -0.4588325050891715, 0.0368511493312198, 0.32495775699122426, 0.46564960359503493, -0.11006395870062427];
    pub const BN_DWEIGHT: &[f64] = &[3.081915818572336, 3.1091494775268185, 3.117489242803656];
    pub const BN_DBIAS: &[f64] = &[-0.010581247324770171, -0.018555649266547763, -0.017803039418229805];
    pub const BN_RUNNING_MEAN: &[f64] = &[5.617712354230586e-05, -0.00016198505486894057, -0.0003039631308890766];
    pub const BN_RUNNING_VAR: &[f64] = &[0.9596340058379856, 0.9598060252591097, 0.96029901593863];
    pub const BN_EVAL_OUT: &[f64] = &[0.46145794364338066, 0.9668106740911188, 0.8068367440670623, -0.10104536574097119, 0.12702025468643152, 1.0103037677982794, -1.2002223682527315, 0.12313758089160828, 0.878010971457709, 0.4721113970992407, 0.9668483057777925, 0.8081189535248103, -0.11725397444650838, 0.11884283383679162, 1.0109811758574752, -1.1945101157766422, 0.13135662732816378, 0.8760447883601419];
    pub const BN_EVAL_DX: &[f64] = &[0.9781030902080701, 0.415153332254766, -0.015531613577151437, -0.5274393011349944, -0.5366964141866425, 0.10962631160158462, -0.4455517370263166, 0.12674485585491274, -0.0951572191702678, 0.9773094188058737, 0.40872312067379984, -0.013546808756254717, -0.5412299691194774, -0.5394294065190394, 0.10883532643097756, -0.43083373560053967, 0.13593454850170258, -0.09634337242681106];
    pub const LN_OUT: &[f64] = &[0.7164946299070967, 0.33787024115160535, -0.811158515367335, -0.7966319040482696, 0.8596114352088, -0.3345970259390792, -0.8669627917766513, -0.8372083877750848, -1.3436058735137222, -2.1382343396944066, 1.4199109993294357, 0.2837687973303893, -0.8238352338961134, -0.5610213670128401, 0.6053316165139244, -0.7829182535896426, -0.7769752071394452, -0.8271864628751182, -1.485357092513297, -1.830340297216858];
    pub const LN_DX: &[f64] = &[-0.9268895424291226, -0.24052918514602095, 0.75314868438806, 0.5175492673054407, -0.10327922411835755, 0.7457674554641375, -0.09223305675726956, -0.676801819605203, -0.20725247231903776, 0.23051989321737232, -0.5864036131680287, 0.26243265904386553, 0.5448319713535045, -0.004416211662378822, -0.21644480556696222, 0.4698127339777799, -0.3669741003555236, -0.4111376986031408, 0.1574428176092839, 0.15085624737160008];
    pub const LN_DA: &[f64] = &[-2.275410363086931, -0.9989529544540182, 0.06567613986418715, -2.0660825491851265, -5.023073079514206];
    pub const LN_DB: &[f64] = &[-0.36447442063908053, -0.639155225128661, -0.6132313401643463, -0.2988951739167389, 0.15601606298983883];
    pub const SOFTMAX_OUT: &[f64] = &[0.07584600222375379, 0.021996058581426104, 0.024600893261813018, 0.10066779498710379, 0.7768892509459033, 0.2690955233098311, 0.48192721686900014, 0.21110532735192436, 0.03334720961184495, 0.004524722857399596, 0.003998507358968333, 0.004629117556967527, 0.019422199979092735, 0.15044780761823157, 0.8215023674867397];
    pub const SOFTMAX_DX: &[f64] = &[-0.12893739575558877, -0.03166035108519846, -0.020452527468755418, -0.01630446587615243, 0.1973547401856951, 0.14346855410848072, 0.03208220752363898, -0.12963576249323333, -0.039639251800354734, -0.006275747338531682, -0.006519886935039101, -0.004709387304810156, -0.006808064698619295, 0.008461030953132024, 0.00957630798533665];
    pub const L1_OUT: &[f64] = &[-0.33390608011726813, 0.0, -0.08166489043288049, 0.1698468190614994, 0.0, 0.46102764057115064, 0.16241307015351866, 0.0, -0.383831126477537, -0.33383403066771383, 0.0, -0.07347634251843192];
    pub const L1_DX: &[f64] = &[-0.0557045953863754, -738582225138.0614, 0.3059850518980205, -0.09802306197805058, 954814525179.6622, 0.08415940609501954, -0.125956043732804, -225486562166.57315, -0.024166267875887604, -0.055433863083636514, -727142500080.8525, 0.3142146399335722];
    pub const MHA_OUT: &[f64] = &[-0.6750334208418034, 2.7272321269636555, -1.8824463176199568, 1.3557034524922593, -1.0867781873062485, 3.1513453344298816, -2.2699194292501517, 1.6617618893987705, -1.3757903867662238, 3.6805734429519155, -2.978208324108731, 2.4672650216432777];
    pub const MHA_DQ: &[f64] = &[-0.5388891420065016, -0.7640443094753867, -0.6298574996763412, -0.19943886598459615, 0.35185673341270524, 0.42627723309079435, 0.3002128892807804, 0.032953732686220996, -0.01546789862508357, -0.047610664513082324, -0.05736139094342387, -0.0401341589166156];
    pub const MHA_DKV: &[f64] = &[-0.10840754865246699, -0.25453935187906773, -0.28095732062985895, -0.1752366714091922, 0.2551441008493099, 0.30837819210217876, 0.2165772010672242, 0.02291656825823627, -0.1006155372264631, -0.09340025236736796, -0.04225736940069905, 0.028759814684730045, 0.31909365696191005, 0.22412925570730988, 0.02375336337733671, -0.1877941069055395, -0.4007400860251711, -0.2839960306183003, -0.03368420445125586, 0.23246982939942865];
    pub const MHA_DWQ: &[f64] = &[0.4372359133987776, 0.020331600029962045, -0.40613498252295893, -0.6415899367611765, -0.28227226325954524, -0.01847154154414027, 0.25401663478527237, 0.4070368186557657, -0.12744483620643104, -0.06270520807706575, 0.03152565920684708, 0.11092951636376641, -0.28079105252581416, -0.04187125241980725, 0.2167412519556018, 0.37341695886080883];
    pub const MHA_DWK: &[f64] = &[0.11254174977409898, -0.03866771060985512, -0.1716911424943493, -0.2239655473156467, 0.05063080523013179, -0.042989611149596235, -0.11639134167446534, -0.1350524055449525, 0.06178149986321593, -0.15536503499984786, -0.299440966256845, -0.3026851321890846, -0.20758638095069842, 0.24236927973784325, 0.5783348810412148, 0.6423005510591109];
    pub const MHA_DWV: &[f64] = &[-0.2191968847371617, 0.06937835799401468, 0.32532387489385917, 0.42826449010535367, -0.2825481551587654, 0.12759704992885326, 0.47773136867603055, 0.603181159976321, 0.3130948260016243, 0.601769816859116, 0.6074230599350008, 0.3273957466763302, 0.1504771723829968, 0.27700026091725816, 0.27324579849366276, 0.14097956745512136];
    pub const MHA_DWO: &[f64] = &[1.4049502504544416, -2.8759779422741647, 0.14309705864327982, -0.5495127815401456, 1.4642265398304666, -2.9604610841262904, 0.03943943926739091, -0.5720258562282947, 0.8348542083534174, -1.6525931196333448, -0.08276716465418993, -0.32550623258171485, -0.18716310226909014, 0.43251521150294864, -0.16604707776628647, 0.07410405842322525];
    pub const MHA_DBQ: &[f64] = &[-0.09082473322565687, 0.07631796395295104, -0.0903419534520675, 0.18887661231146474];
    pub const MHA_DBO: &[f64] = &[-0.8444806284587656, -0.8152328386057596, -0.4025683063919745, 0.19943039062124934];
    pub const MAXK_OUT: &[f64] = &[0.9906073556948704, 0.8457468311429343, 0.8366556385360561, 0.9927664058359071, 0.9946447738778381, 0.8273279005953806];
    pub const MAXK_DX: &[f64] = &[-0.9992068341863537, -0.7385822251380614, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5388194348720935, -0.1305908549417222, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.9548145251796623, 0.9217454249067293, 0.0, 0.0, 0.0, 0.0];
    pub const SGD_AFTER_3: &[f64] = &[1.0410880501533528, 0.5543256638652047, -0.19314474371616847, -0.8497761603579632, -1.1067445706646262, -0.843193716026767];
    pub const ADAM_AFTER_3: &[f64] = &[0.7726738575395223, 0.16918098934736428, -0.5063244345516924, -0.93815721549068, -0.9286051431779324, -0.49301490430154776];
}
